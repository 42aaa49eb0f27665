import csv
import itertools
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from conftest import ROOT, run_main
from scipy import stats

import plot_results as plots
from paper_study import aggregate as aggregation
from paper_study import figures, paper
from paper_study.figures import PAPER_DROPOUT_FIGURE_YLIM
from paper_study.stats import (
    bootstrap_coverage,
    detectable_gap,
    hedges_g,
    holm,
    median_relative_gap,
    null_rates,
    performance_profile,
    sd_from_ci,
    sign_test,
    welch,
    welch_power,
)
from pgg_utils import identity
from pgg_utils.files import LOCK_FILE, lock_directory, read_csv, read_manifest, write_record

# Per-seed mean returns of the synthetic sweep: (env, variant, step, eval γ) -> three seed means.
# Two episodes per seed, at mean ± 1. With means m, m+1, m+2 the summary is (m+1) ± t(.975,2)·1/√3 = ± 2.5.
SEED_MEANS = {
    ("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272],  # paper 270.6 ± 81.3: agrees
    ("CartPole-v1", "ppo", 200000, 1.0): [300, 301, 302],  # paper 456.6 ± 50.8: disagrees
    ("CartPole-v1", "pgg_g1.1", 100000, 1.0): [336, 337, 338],  # paper 337.8 ± 96.4: agrees
    ("CartPole-v1", "pgg_g1.1", 100000, 2.0): [100, 101, 102],  # paper 393.0 ± 132.1: disagrees
    ("CartPole-v1", "pgg_g1.1", 200000, 1.0): [466, 467, 468],  # paper 466.8 ± 27.5: agrees
    ("CartPole-v1", "pgg_g1.1", 200000, 2.0): [497, 498, 499],  # paper 500.0 ± 0.0: agrees (returns stay <= 500)
    ("Acrobot-v1", "ppo", 100000, 1.0): [-201, -200, -199],  # paper -111.3 ± 7.5: disagrees
    ("Acrobot-v1", "ppo", 200000, 1.0): [-86, -85, -84],  # paper -85.6 ± 3.1: agrees
    ("Acrobot-v1", "pgg_g1.1", 100000, 1.0): [-112, -111, -110],
    ("Acrobot-v1", "pgg_g1.1", 100000, 2.0): [-94, -93, -92],
    ("Acrobot-v1", "pgg_g1.1", 200000, 1.0): [-87, -86, -85],
    ("Acrobot-v1", "pgg_g1.1", 200000, 2.0): [-84, -83, -82],
}
DISAGREEING = {("CartPole-v1", "ppo", 200000, 1.0), ("CartPole-v1", "pgg_g1.1", 100000, 2.0),
               ("Acrobot-v1", "ppo", 100000, 1.0)}  # fmt: skip
HALF_WIDTH = 4.302653 / 3**0.5  # t_{0.975,2} · s / √n with s = 1, n = 3
COLUMNS = ["env_id", "variant", "run", "seed", "train_guidance", "cond_dropout", "step", "global_step", "eval_guidance",
           "policy", "null_branch", "episode", "episode_seed", "return", "length"]  # fmt: skip


def episode_rows(
    seed_means: dict, config: str | None = None, run_suffix: str = "", policy="sample", action_space: str | None = None
) -> list[dict]:
    rows = []
    for (env, variant, step, gamma), means in seed_means.items():
        for seed, mean in enumerate(means, start=1):
            for episode, ret in enumerate([mean - 1, mean + 1]):
                row = {"env_id": env, "variant": variant, "run": f"{env}__{variant}__s{seed}{run_suffix}", "seed": seed,
                       "train_guidance": 1.1 if variant != "ppo" else 1.0, "cond_dropout": 0.0, "step": step,
                       "global_step": step, "eval_guidance": gamma, "policy": policy, "null_branch": "learned",
                       "episode": episode, "episode_seed": 10_000 + episode, "return": ret, "length": 1}  # fmt: skip
                if config is not None:
                    row["config"] = config if " " in config else f"{variant} {config}".strip()
                if action_space is not None:
                    row["action_space"] = action_space
                rows.append(row)
    return rows


def write_episodes(path, rows) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = COLUMNS + [c for c in ("config", "config_fields", "action_space") if any(c in r for r in rows)]
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        writer.writerows(rows)


@pytest.fixture
def sweep_dir(tmp_path):
    write_episodes(tmp_path / "sweep" / "episodes.csv", episode_rows(SEED_MEANS))
    return tmp_path / "sweep"


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """One plot_results run on SEED_MEANS with the default arguments, which several tests read (and none
    writes to): (the sweep folder, the output folder, the paths it wrote)."""
    tmp_path = tmp_path_factory.mktemp("plots")
    write_episodes(tmp_path / "sweep" / "episodes.csv", episode_rows(SEED_MEANS))
    written = generate(tmp_path / "sweep", tmp_path)
    return tmp_path / "sweep", tmp_path / "out", written


def generate(sweep_dir, tmp_path, **kw):
    return plots.generate(plots.Args(sweeps=(str(sweep_dir),), output=str(tmp_path / "out"), **kw))


def summary_of(*paths, provenance=None):
    return plots.summarise(plots.select_mode(plots.read_episodes(paths), "sample", "learned"),
                           plots.read_provenance(provenance))  # fmt: skip


def run_cli(*args, cwd=None):
    """`python plot_results.py *args`, its main in this process (conftest.run_main: no Python start-up per call;
    test_plot_results_imports_neither_torch_nor_the_training_scripts starts the real command)."""
    return run_main(plots, *args, cwd=cwd)


def one_error_line(proc, message: str) -> None:
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2, proc.stderr
    assert len(errors) == 1 and message in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr


# --- tables ---------------------------------------------------------------------------------------


def test_tables_hold_expected_cells(generated):
    _, out, _ = generated
    markdown = (out / "table_discrete.md").read_text().splitlines()
    assert markdown[2] == "| Method | Acrobot-v1 | CartPole-v1 |"
    section = markdown.index("| **100k Steps** | | |")
    assert markdown[section + 1] == f"| PPO | -200.0 ± {HALF_WIDTH:.1f} | 271.0 ± {HALF_WIDTH:.1f} |"
    assert markdown[section + 2] == "| pgg_g1.1 |  |  |"
    assert markdown[section + 4] == f"|   γ=2 | -93.0 ± {HALF_WIDTH:.1f} | 101.0 ± {HALF_WIDTH:.1f} |"
    latex = (out / "table_discrete.tex").read_text()
    assert f"\\quad $\\gamma=2$ & $-93.0 \\pm {HALF_WIDTH:.1f}$ & $101.0 \\pm {HALF_WIDTH:.1f}$ \\\\" in latex
    assert "\\multicolumn{3}{l}{\\textbf{200k Steps}} \\\\" in latex


def test_latex_is_well_formed(generated):
    _, out, _ = generated
    latex = (out / "table_discrete.tex").read_text()
    begins, ends = re.findall(r"\\begin\{(\w+)\}", latex), re.findall(r"\\end\{(\w+)\}", latex)
    assert sorted(begins) == sorted(ends) == sorted(["document", "table", "tabular"])
    assert latex.count("{") == latex.count("}")
    tabular = latex.split("\\begin{tabular}{lcc}")[1].split("\\end{tabular}")[0]
    rows = [line for line in tabular.splitlines() if line.endswith("\\\\") and "multicolumn" not in line]
    assert rows and all(row.count("&") == 2 for row in rows)
    assert all(line.count("$") % 2 == 0 for line in tabular.splitlines())


# --- the agreement test ---------------------------------------------------------------------------


def test_welch_and_effect_size_match_hand_computed_values():
    # ours 10 (sd 1, n 5) vs 12 (sd 2, n 5): t = -2 / sqrt(1/5 + 4/5) = -2; df = 1 / (0.2²/4 + 0.8²/4) = 5.882
    t_value, df, p = welch(10, 1, 5, 12, 2, 5)
    assert t_value == pytest.approx(-2.0) and df == pytest.approx(1 / 0.17)
    assert p == pytest.approx(stats.ttest_ind_from_stats(10, 1, 5, 12, 2, 5, equal_var=False).pvalue, rel=1e-12)
    assert p == pytest.approx(0.0933789, abs=1e-6)
    # Hedges' g: pooled sd 2, d = 1, J = 1 - 3 / (4·10 - 9) = 28/31
    assert hedges_g(12, 2, 5, 10, 2, 5) == pytest.approx(28 / 31)
    # the paper's 270.6 ± 81.3 over 5 seeds: sd = 81.3 · √5 / t_{0.975,4}
    assert sd_from_ci(81.3, 5) == pytest.approx(65.47665, abs=1e-4)
    assert welch(500, 0, 5, 500, 0, 5)[2] == 1.0 and welch(500, 0, 5, 499, 0, 5)[2] == 0.0


def test_holm_adjusts_in_step_down_order_and_keeps_nans():
    # sorted 0.005·4 = 0.02, 0.01·3 = 0.03, 0.03·2 = 0.06, max(0.04·1, 0.06) = 0.06
    adjusted = holm([0.01, 0.04, math.nan, 0.03, 0.005])
    assert adjusted[:2] == pytest.approx([0.03, 0.06]) and math.isnan(adjusted[2])
    assert adjusted[3:] == pytest.approx([0.06, 0.02])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])


def test_sign_test_counts_above_below_and_ties():
    above, below, ties, p = sign_test([1.0, 2.0, 3.0, -1.0, 0.0])
    assert (above, below, ties) == (3, 1, 1) and p == pytest.approx(0.625)
    assert sign_test([-1.0] * 10)[3] == pytest.approx(2 * 0.5**10)


def test_simulated_null_overlap_rate_is_near_certain():
    rates = null_rates(5, draws=20_000, shifts=(0.0, 2.0))
    assert 0.99 < rates[0]["overlap"] < 0.998  # 99.4% for two 5-seed samples of one distribution
    assert rates[0]["welch_reject"] < 0.06 < rates[1]["welch_reject"]


def welch_rejections(gap, sd1, sd2, n, alpha, draws=20_000, seed=0) -> float:
    """Monte Carlo: how often Welch's test (scipy's) rejects at `alpha` for normal samples whose means differ
    by `gap`."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((draws, n)) * sd1
    b = rng.standard_normal((draws, n)) * sd2 + gap
    return float((stats.ttest_ind(a, b, axis=1, equal_var=False).pvalue < alpha).mean())


@pytest.mark.parametrize("sd1, sd2, alpha", [(1.0, 1.0, 0.05 / 270), (827.0, 65.0, 0.05 / 270), (1.0, 3.0, 0.05),
                                             (0.0, 2.0, 0.05 / 70)])  # fmt: skip
def test_a_gap_of_the_detectable_size_is_detected_80_percent_of_the_time(sd1, sd2, alpha):
    # equal sds at Holm's first step over 270 cells (where the noncentral-t approximation says 80% and gives 63%),
    # HalfCheetah's 1M PPO cell (the paper's sd 827, ours 65), unequal sds at 0.05, one side without spread
    gap = detectable_gap(sd1, 5, sd2, 5, alpha)
    assert welch_power(gap, sd1, 5, sd2, 5, alpha) == pytest.approx(0.8, abs=1e-6)
    assert welch_rejections(gap, sd1, sd2, 5, alpha) == pytest.approx(0.8, abs=0.015)
    assert welch_rejections(0.8 * gap, sd1, sd2, 5, alpha) < 0.7  # and a smaller gap is missed more often


def test_detectable_gap_scales_with_the_spread_and_is_undefined_without_one():
    one = detectable_gap(1.0, 5, 1.0, 5, 0.05 / 270)
    assert 5.5 < one < 6.1  # about 6 sds with 5 seeds a side at α/270
    assert detectable_gap(10.0, 5, 10.0, 5, 0.05 / 270) == pytest.approx(10 * one, rel=1e-6)
    assert math.isnan(detectable_gap(0.0, 5, 0.0, 5, 0.05)) and math.isnan(detectable_gap(1.0, 1, 1.0, 5, 0.05))


def test_median_relative_gap_resamples_seeds_per_run_set_with_the_references_fixed():
    x = np.array([90.0, 95.0, 100.0, 105.0, 130.0])
    two_cells = [(np.stack([x, x + 10]), np.array([100.0, 110.0]))]  # one run set: its two cells share the seed draws
    # 5 seeds: the bootstrap enumerated, its percentiles those of all 3,125 equally likely draws
    every = np.array(list(itertools.product(range(5), repeat=5)))
    gaps = np.sort(np.median([(x[every].mean(1) - 100) / 100, (x[every].mean(1) + 10 - 110) / 110], axis=0))
    assert median_relative_gap(two_cells)[1:] == pytest.approx(
        (gaps[78 - 1], gaps[3047 - 1])
    )  # ⌈0.025·3125⌉, ⌈0.975·3125⌉
    # too many to enumerate: Monte Carlo draws
    median, low, high = median_relative_gap(two_cells, resamples=2000, seed=0, exact_limit=0)
    draws = np.random.default_rng(0).integers(0, 5, size=(2000, 5))
    first, second = (x[draws].mean(1) - 100) / 100, (x[draws].mean(1) + 10 - 110) / 110
    expected_low, expected_high = np.percentile(np.median(np.stack([first, second]), axis=0), [2.5, 97.5])
    assert median == pytest.approx(np.median([(x.mean() - 100) / 100, (x.mean() - 100) / 110]))
    assert (low, high) == pytest.approx((expected_low, expected_high))
    assert median_relative_gap([(np.full((3, 5), 50.0), np.array([100.0, 100.0, 100.0]))]) == (-0.5, -0.5, -0.5)
    assert 0.78 < bootstrap_coverage(5) < 0.90  # a 5-seed percentile interval is narrow: the report says so


@pytest.mark.slow
def test_comparison_tests_each_cell_and_corrects_over_the_table(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path, compare_paper=True)
    with open(tmp_path / "out" / "compare_paper.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["reference"] == "paper"]
    key = lambda r: (r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"]))
    assert {key(r) for r in rows} == set(SEED_MEANS)
    paper = {(p["env_id"], p["method"], int(p["step"]), float(p["eval_guidance"])): p
             for p in read_csv(ROOT / "paper_study" / "data" / "paper_results.csv")}  # fmt: skip
    expected_p = []
    for r in rows:
        p = paper[(r["env_id"], "ppo" if r["variant"] == "ppo" else "pgg", int(r["step"]), float(r["eval_guidance"]))]
        ours = SEED_MEANS[key(r)]
        sd_paper = float(p["ci95"]) * 5**0.5 / stats.t.ppf(0.975, 4)
        expected = stats.ttest_ind_from_stats(np.mean(ours), np.std(ours, ddof=1), 3, float(p["mean"]), sd_paper, 5,
                                              equal_var=False).pvalue  # fmt: skip
        expected_p.append(1.0 if np.isnan(expected) else expected)  # 500 ± 0 vs 500 ± 1: p computed, not nan
        assert float(r["p"]) == pytest.approx(expected_p[-1], rel=1e-3, abs=1e-4)
        assert float(r["diff_pct"]) == pytest.approx(
            100 * (np.mean(ours) - float(p["mean"])) / abs(float(p["mean"])), abs=1e-3
        )
    m = len(rows)  # Holm over the cells of the discrete table
    order = np.argsort(expected_p)
    holm = np.maximum.accumulate([min(1.0, (m - i) * expected_p[j]) for i, j in enumerate(order)])
    for i, j in enumerate(order):
        assert float(rows[j]["p_holm"]) == pytest.approx(holm[i], rel=1e-3, abs=1e-4)
    assert {key(r) for r in rows if r["significant"] == "True"} == DISAGREEING
    assert {key(r) for r in rows if r["ci_overlap"] == "False"} == DISAGREEING
    report = (tmp_path / "out" / "compare_paper.md").read_text()
    assert "**3 of 12 differ significantly**" in report and "Holm-corrected over these 12 cells" in report
    assert "**CartPole-v1**: 6 cells; **2 differ significantly after Holm**" in report
    assert "99.4%" in report or "99.3%" in report or "99.5%" in report  # the simulated null overlap rate


@pytest.mark.slow
def test_the_report_says_what_each_test_can_see_and_pools_a_task_with_a_bootstrap(sweep_dir, tmp_path):
    generate(sweep_dir, tmp_path, compare_paper=True)
    rows = [r for r in read_csv(tmp_path / "out" / "compare_paper.csv") if r["reference"] == "paper"]
    for r in rows:  # per cell: the gap found 80% of the time at Holm's first step, α/12, from the cell's two sds
        expected = detectable_gap(float(r["our_sd"]), 3, float(r["ref_sd"]), 5, 0.05 / 12)
        assert float(r["detectable_gap"]) == pytest.approx(expected, rel=1e-3)
        assert float(r["detectable_gap_pct"]) == pytest.approx(100 * expected / abs(float(r["ref_mean"])), rel=1e-3)
    tasks = {t["env_id"]: t for t in read_csv(tmp_path / "out" / "compare_paper_tasks.csv")}
    assert set(tasks) == {"Acrobot-v1", "CartPole-v1"}
    report = (tmp_path / "out" / "compare_paper.md").read_text()
    assert "| env | cells | differ after Holm | gap detected 80% of the time (median) |" in report
    assert "holds the paper's means fixed" in report
    for env, task in tasks.items():
        cells = [r for r in rows if r["env_id"] == env]
        assert float(task["holm_first_alpha"]) == pytest.approx(0.05 / 12, rel=0.01)  # the CSV keeps 4 decimals
        gaps = [float(r["detectable_gap"]) for r in cells]
        assert float(task["detectable_gap_median"]) == pytest.approx(np.median(gaps), rel=1e-3)
        assert float(task["rel_gap_median_pct"]) == pytest.approx(
            np.median([float(r["diff_pct"]) for r in cells]), abs=1e-2
        )
        assert (
            float(task["rel_gap_ci_low_pct"]) <= float(task["rel_gap_median_pct"]) <= float(task["rel_gap_ci_high_pct"])
        )
        gap = f"{float(task['rel_gap_median_pct']):+.1f}%".replace("-", "−")
        assert (
            f"| {env} | {len(cells)} | {task['significant']} | {float(task['detectable_gap_median']):.1f} |" in report
        )
        assert gap in report


@pytest.mark.slow
def test_cleanrl_is_a_second_reference_for_final_ppo(tmp_path):
    means = {
        ("CartPole-v1", "ppo", 500000, 1.0): [489.0, 490.0, 491.0],
        ("CartPole-v1", "ppo", 400000, 1.0): [480.0, 481.0, 482.0],
    }
    write_episodes(tmp_path / "episodes.csv", episode_rows(means))
    plots.generate(
        plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out"), compare_paper=True)
    )
    rows = read_csv(tmp_path / "out" / "compare_paper.csv")
    cleanrl = [r for r in rows if r["reference"] == "cleanrl"]
    assert len(cleanrl) == 1 and cleanrl[0]["step"] == "500000"
    assert float(cleanrl[0]["ref_mean"]) == 490.04
    assert float(cleanrl[0]["ref_sd"]) == pytest.approx(6.12 * 1.5**0.5, abs=1e-3)  # CleanRL's std has ddof 0, 3 seeds
    assert "mean ± standard deviation" in (tmp_path / "out" / "compare_paper.md").read_text()


@pytest.mark.slow
def test_compare_paper_compares_the_papers_configurations_only_and_names_the_rest(tmp_path):
    """A reward-scaled fork's CartPole PPO (returns a tenth of the task's) was compared with the paper
    (−86.2%) and nothing named the fork: a fork, or a run with another training argument, is left out of
    the comparison and named in the report and on stderr; the paper's own configuration is compared."""
    cell = ("CartPole-v1", "ppo", 500000, 1.0)
    own = episode_rows({cell: [489.0, 490.0, 491.0]})  # config: the variant alone
    fork = episode_rows({cell: [48.9, 49.0, 49.1]}, config="ppo script=ppo_pgg_scaled.py", run_suffix="_fork")
    shorter = episode_rows({cell: [300.0, 301.0, 302.0]}, config="ppo learning_rate=0.002", run_suffix="_lr")
    write_episodes(tmp_path / "episodes.csv", own + fork + shorter)
    proc = run_cli(tmp_path / "episodes.csv", "--compare-paper", "--output", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    named = "CartPole-v1 `ppo learning_rate=0.002`; CartPole-v1 `ppo script=ppo_pgg_scaled.py`"
    assert f"note: left out of the comparison with the paper, not its configuration: {named}" in proc.stderr
    rows = read_csv(tmp_path / "out" / "compare_paper.csv")
    assert {r["config"] for r in rows} == {"ppo"} and {float(r["our_mean"]) for r in rows} == {490.0}
    assert (
        f"Left out, not the paper's configuration (a fork, or training arguments other than the paper's): {named}."
        in (tmp_path / "out" / "compare_paper.md").read_text()
    )
    write_episodes(tmp_path / "fork.csv", fork)  # the fork alone: nothing is compared, and it is named
    proc = run_cli(tmp_path / "fork.csv", "--compare-paper", "--output", tmp_path / "fork_out")
    assert proc.returncode == 0 and "CartPole-v1 `ppo script=ppo_pgg_scaled.py`" in proc.stderr
    assert not (tmp_path / "fork_out" / "compare_paper.csv").exists()
    assert "No cell compared" in (tmp_path / "fork_out" / "compare_paper.md").read_text()
    assert paper.is_paper_configuration({"variant": "pgg_g1.1", "config_fields": {"mujoco": "2.3.7"}})
    assert not paper.is_paper_configuration({"variant": "ppo", "config_fields": {"null": "bc"}})


# --- configurations -------------------------------------------------------------------------------


@pytest.mark.slow
def test_two_configs_are_never_pooled(tmp_path):
    cell = ("CartPole-v1", "ppo", 100000, 1.0)
    default = episode_rows({cell: [190.0]}, config="ppo")
    faster = episode_rows({cell: [366.0]}, config="learning_rate=0.002", run_suffix="_lr")
    write_episodes(tmp_path / "episodes.csv", default + faster)
    summary = summary_of(tmp_path / "episodes.csv")
    assert sorted((r["series"], r["n_seeds"], r["mean"]) for r in summary) == [
        ("learning_rate=0.002", 1, 366.0), ("learning_rate=default", 1, 190.0)]  # fmt: skip
    plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    table = (tmp_path / "out" / "table_discrete.md").read_text()
    assert "| PPO [learning_rate=0.002] | 366.0 |" in table and "| PPO [learning_rate=default] | 190.0 |" in table
    fig = figures.figure_for_variant(summary, ["CartPole-v1"], "pgg_g1.1")
    labels = {
        line.get_label(): list(line.get_ydata())
        for line in fig.axes[0].get_lines()
        if not line.get_label().startswith("_")
    }
    assert labels == {}  # no PGG data: the panel says "not run" instead of drawing PPO alone
    fig = figures.figure_for_variant(summary, ["CartPole-v1"], "ppo")
    labels = {
        line.get_label(): list(line.get_ydata())
        for line in fig.axes[0].get_lines()
        if not line.get_label().startswith("_")
    }
    assert labels == {"PPO [learning_rate=0.002] (γ = 1)": [366.0], "PPO [learning_rate=default] (γ = 1)": [190.0]}


def test_configurations_are_told_apart_by_their_fields_never_by_their_labels_words(tmp_path):
    """Two values of a fork's argument that hold a space (`leaky relu`, `leaky tanh`): the labels' words
    cannot tell them apart, the sweep's config_fields column does, and the series name each value whole.
    An edited config_fields that no longer spells its label is refused in one line."""
    cell = ("CartPole-v1", "ppo", 100000, 1.0)
    rows = []
    for activation, mean in (("leaky relu", 190.0), ("leaky tanh", 366.0)):
        args = {"env_id": "CartPole-v1", "seed": 1, "guidance": 1.0, "activation": activation}
        fields = identity.Configuration("discrete", "ppo_fork.py", args, versions={"torch": "2.13.0"}).fields()
        assert json.loads(fields["config_fields"]) == {"script": "ppo_fork.py", "activation": activation}
        rows += [r | {"config": fields["config"], "config_fields": fields["config_fields"]}
                 for r in episode_rows({cell: [mean]}, run_suffix=activation[-4:])]  # fmt: skip
    write_episodes(tmp_path / "episodes.csv", rows)
    summary = summary_of(tmp_path / "episodes.csv")
    assert sorted((r["series"], r["mean"]) for r in summary) == [("activation=leaky relu script=ppo_fork.py", 190.0),
                                                                ("activation=leaky tanh script=ppo_fork.py", 366.0)]  # fmt: skip
    assert not any(paper.is_paper_configuration(r) for r in summary)
    with pytest.raises(ValueError, match="an argument named script would hide the label's own field"):
        identity.Configuration(
            "discrete", "ppo_fork.py", {**args, "script": "x"}, versions={"torch": "2.13.0"}
        ).fields()
    write_episodes(tmp_path / "edited.csv", [r | {"config_fields": '{"activation": "leaky"}'} for r in rows])
    with pytest.raises(
        plots.InputError, match=r"edited.csv, line 2: config_fields .* is not the JSON object of its config"
    ):
        plots.read_episodes([tmp_path / "edited.csv"])


def test_one_config_shows_the_paper_name_without_a_label(tmp_path):
    write_episodes(tmp_path / "episodes.csv", episode_rows(SEED_MEANS, config="mujoco=2.3.7"))
    summary = summary_of(tmp_path / "episodes.csv")
    assert {r["series"] for r in summary} == {""}
    assert {r["config"] for r in summary} == {"ppo mujoco=2.3.7", "pgg_g1.1 mujoco=2.3.7"}


def test_same_config_and_seed_from_two_runs_is_an_error_naming_both(tmp_path):
    cell = {("CartPole-v1", "ppo", 100000, 1.0): [190.0]}
    write_episodes(tmp_path / "a.csv", episode_rows(cell, run_suffix="_a"))
    write_episodes(tmp_path / "b.csv", episode_rows(cell, run_suffix="_b"))
    with pytest.raises(plots.InputError, match="CartPole-v1__ppo__s1_a .*a.csv.* and CartPole-v1__ppo__s1_b .*b.csv"):
        plots.read_episodes([tmp_path / "a.csv", tmp_path / "b.csv"])
    with pytest.raises(plots.InputError, match="appears in .*a.csv twice"):
        plots.read_episodes([tmp_path / "a.csv", tmp_path / "a.csv"])
    (tmp_path / "copy.csv").write_text((tmp_path / "a.csv").read_text())
    with pytest.raises(plots.InputError, match="appears in both .*a.csv and .*copy.csv"):
        plots.read_episodes([tmp_path / "a.csv", tmp_path / "copy.csv"])


@pytest.mark.slow
def test_configurations_are_grouped_on_their_exact_guidance(tmp_path):
    """γ_train 1.1 and 1.1000000001 share a variant and config label (both print as `pgg_g1.1`) and, with
    default run names, a run name per seed: still two configurations, neither pooled nor refused."""
    cell = {("CartPole-v1", "pgg_g1.1", 100000, 1.0): [300.0, 301.0, 302.0]}
    nearby = [r | {"train_guidance": 1.1000000001, "return": r["return"] + 100} for r in episode_rows(cell)]
    write_episodes(tmp_path / "episodes.csv", episode_rows(cell) + nearby)
    summary = summary_of(tmp_path / "episodes.csv")
    assert sorted((r["series"], r["train_guidance"], r["n_seeds"], r["mean"]) for r in summary) == [
        ("guidance=1.1", 1.1, 3, 301.0), ("guidance=1.1000000001", 1.1000000001, 3, 401.0)]  # fmt: skip
    plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    table = (tmp_path / "out" / "table_discrete.md").read_text()
    assert "| pgg_g1.1 [guidance=1.1] |" in table and "| pgg_g1.1 [guidance=1.1000000001] |" in table


@pytest.mark.slow
def test_cells_from_another_mujoco_are_marked(tmp_path):
    hopper = {
        ("Hopper-v4", "ppo", 200000, 1.0): [1000.0, 1100.0, 1200.0],
        ("Walker2d-v4", "ppo", 200000, 1.0): [800.0, 810.0, 820.0],
    }
    rows = episode_rows(hopper)
    write_episodes(tmp_path / "here" / "episodes.csv", [r for r in rows if r["env_id"] == "Hopper-v4"])
    write_episodes(tmp_path / "there" / "episodes.csv", [r for r in rows if r["env_id"] == "Walker2d-v4"])
    provenance = tmp_path / "provenance.csv"
    provenance.write_text("csv,commits,mujoco,machine,notes\n"
                          f"{tmp_path / 'here' / 'episodes.csv'},abc1234,2.3.7,two cores,\n"
                          f"{tmp_path / 'there' / 'episodes.csv'},def5678,3.1.6,sixteen cores,\n")  # fmt: skip
    written = plots.generate(plots.Args(sweeps=(str(tmp_path / "here"), str(tmp_path / "there")), output=str(tmp_path / "out"),
                                        provenance=str(provenance)))  # fmt: skip
    table = (tmp_path / "out" / "table_continuous.md").read_text()
    assert "| PPO | 1100.0 ± 248.4 | 810.0 ± 24.8† |" in table
    assert "† from a MuJoCo other than 2.3.7: Walker2d-v4 (MuJoCo 3.1.6)" in table
    assert "Not run" not in table  # the tasks not swept are not the user's to run
    assert "$^\\dagger$" in (tmp_path / "out" / "table_continuous.tex").read_text()
    provenance_md = (tmp_path / "out" / "provenance.md").read_text()
    assert "def5678 | 3.1.6 | sixteen cores" in provenance_md and "abc1234 | 2.3.7 | two cores" in provenance_md
    assert tmp_path / "out" / "provenance.md" in written
    summary = summary_of(tmp_path / "here", tmp_path / "there", provenance=str(provenance))
    assert (
        figures.panel_title("Walker2d-v4", [r for r in summary if r["env_id"] == "Walker2d-v4"])
        == "Walker2d-v4 (3 seeds, MuJoCo 3.1.6)"
    )
    walker = [r for r in summary if r["env_id"] == "Walker2d-v4"]
    mixed = walker + [dict(r, variant="pgg_drop0.1", mujoco="2.3.7") for r in walker]
    assert figures.panel_title("Walker2d-v4", mixed) == "Walker2d-v4 (3 seeds, PPO on MuJoCo 3.1.6)"


# --- what plot_results needs, where an env belongs, what a rerun leaves ----------------------------


@pytest.mark.slow
def test_plot_results_imports_neither_torch_nor_the_training_scripts():
    """Tables from committed CSVs, and a usage error, need no torch (seconds to import) and no training code."""
    code = ("import plot_results, sys; assert 'torch' not in sys.modules; "
            "assert not {'eval_gamma_sweep', 'ppo_pgg_discrete', 'ppo_pgg_continuous', 'pgg_utils.sweep'} & set(sys.modules)")  # fmt: skip
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT, check=False
    )
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("env,action_space", [("Pendulum-v1", None), ("Pendulum-v1", "continuous"),
                                              ("LunarLanderContinuous-v3", "continuous")])  # fmt: skip
def test_an_env_is_tabled_by_its_action_space_not_its_name(tmp_path, env, action_space):
    """Pendulum-v1 and LunarLanderContinuous-v3 act continuously, whatever their version suffix: by the
    rows' action_space where the sweep recorded it, else by the task's own action space (here Pendulum's;
    CartPole's rows leave the column empty)."""
    rows = episode_rows({(env, "ppo", 100000, 1.0): [-900.0, -800.0, -700.0]}, action_space=action_space)
    rows += episode_rows({("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272]})
    write_episodes(tmp_path / "episodes.csv", rows)
    assert {(r["env_id"], r["kind"]) for r in summary_of(tmp_path / "episodes.csv")} == {
        (env, "continuous"), ("CartPole-v1", "discrete")}  # fmt: skip
    plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    assert (tmp_path / "out" / "table_continuous.md").read_text().splitlines()[2] == f"| Method | {env} |"
    assert (tmp_path / "out" / "table_discrete.md").read_text().splitlines()[2] == "| Method | CartPole-v1 |"


@pytest.mark.slow
def test_a_rerun_removes_the_outputs_of_the_previous_run_it_does_not_write_again(tmp_path, monkeypatch):
    both = {("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272], ("Hopper-v4", "ppo", 200000, 1.0): [1000, 1100, 1200]}
    write_episodes(tmp_path / "both.csv", episode_rows(both))
    write_episodes(tmp_path / "cartpole.csv", episode_rows({k: v for k, v in both.items() if k[0] == "CartPole-v1"}))
    out, outside = tmp_path / "out", tmp_path / "outside.md"

    def run(sweep: str) -> list:
        return plots.generate(plots.Args(sweeps=(str(tmp_path / sweep),), output=str(out)))

    def listed() -> set:
        return set(read_manifest(out))

    first = run("both.csv")
    assert out / "outputs.txt" in first and listed() == {p.name for p in first} - {"outputs.txt"}
    assert (out / "table_continuous.md").exists() and (out / "fig_continuous_ppo.png").exists()
    (out / "notes.md").write_text("not plot_results'")
    (out / "learning_curves.png").write_bytes(b"of an earlier run with --runs, before manifests")
    outside.write_text("outside the folder")
    (out / "outputs.txt").write_text((out / "outputs.txt").read_text() + "../outside.md\n")
    second = run("cartpole.csv")
    assert {p.name for p in out.iterdir()} == {p.name for p in second} | {"notes.md", "learning_curves.png", LOCK_FILE}
    assert not (out / "table_continuous.md").exists() and outside.exists()
    assert listed() == {p.name for p in second} - {"outputs.txt"}

    def interrupted(summary):
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "aggregate_iqm", interrupted)  # after the tables and figures are written
    with pytest.raises(KeyboardInterrupt):
        run("both.csv")
    assert {"table_continuous.md", "aggregate_iqm.md"} <= listed()  # this run's files and the previous run's
    monkeypatch.undo()
    third = run("cartpole.csv")
    assert {p.name for p in out.iterdir()} == {p.name for p in third} | {"notes.md", "learning_curves.png", LOCK_FILE}


# --- figures --------------------------------------------------------------------------------------


def legend_labels(fig) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def test_figures_use_paper_names_and_order(generated):
    sweep_dir, _, written = generated
    summary = summary_of(sweep_dir)
    fig = figures.figure_for_variant(summary, ["Acrobot-v1", "CartPole-v1"], "pgg_g1.1")
    for ax in fig.axes:
        lines = [line for line in ax.get_lines() if not line.get_label().startswith("_")]  # not error-bar caps
        assert [line.get_label() for line in lines] == ["PPO (γ = 1)", "γ = 1", "γ = 2"]
        ppo, gamma1, gamma2 = lines
        assert ppo.get_color() == "black" and ppo.get_linestyle() == "-" and gamma2.get_linestyle() == "--"
        assert gamma1.get_marker() != gamma2.get_marker()  # stacked lines stay apart
        assert len(ax.collections) >= 3  # one CI band (and error bars) per line
    assert legend_labels(fig) == ["PPO (γ = 1)", "γ = 2", "γ = 1"]  # the paper's order: PPO, then the highest γ first
    assert fig._suptitle.get_text().startswith("PGG, γ_train = 1.1")
    assert "pgg_g1.1" not in fig._suptitle.get_text() and "checkpoints, eval guidance" not in fig._suptitle.get_text()
    cartpole = next(line for line in fig.axes[1].get_lines() if line.get_label() == "γ = 2")
    assert list(cartpole.get_ydata()) == [101.0, 498.0]
    ppo_fig = figures.figure_for_variant(summary, ["Acrobot-v1", "CartPole-v1"], "ppo")
    assert ppo_fig._suptitle.get_text().startswith("PPO")
    for path in written:
        if path.suffix in (".png", ".pdf"):
            head = path.read_bytes()[:8]
            assert head.startswith((b"\x89PNG", b"%PDF"))
            assert 5_000 < path.stat().st_size < 5_000_000


@pytest.mark.slow
def test_figures_draw_the_tasks_swept_in_the_papers_order_and_no_task_never_run(tmp_path):
    means = {
        ("Hopper-v4", "ppo", 200000, 1.0): [1000.0, 1100.0, 1200.0],
        ("Hopper-v4", "pgg_g1.1", 200000, 1.0): [900.0, 950.0, 1000.0],
        ("HalfCheetah-v4", "ppo", 200000, 1.0): [1000.0, 1100.0, 1200.0],
    }
    write_episodes(tmp_path / "episodes.csv", episode_rows(means))
    written = plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    names = {p.name for p in written}
    assert {"fig_continuous_ppo.png", "fig_continuous_pgg_g1.1.png"} <= names
    assert "fig_continuous_pgg_drop0.1.png" not in names  # a variant never trained has no figure
    assert "Not run" not in (tmp_path / "out" / "table_continuous.md").read_text()
    summary = summary_of(tmp_path / "episodes.csv")
    layout, cols = figures.figure_layout("continuous", ["Hopper-v4", "HalfCheetah-v4"])
    assert layout == ["HalfCheetah-v4", "Hopper-v4"] and cols == 2  # the paper's order
    fig = figures.figure_for_variant(summary, ["HalfCheetah-v4", "Hopper-v4"], "pgg_g1.1", layout, cols)
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.get_title()]
    # HalfCheetah was trained, though not with this variant: its panel says so; no other task is drawn
    not_run = [ax.get_title() for ax in panels if any(t.get_text() == "not run" for t in ax.texts)]
    assert len(panels) == 2 and not_run == ["HalfCheetah-v4"]
    assert figures.figure_layout("continuous", list(paper.PAPER_ENVS["continuous"]))[1] == 3  # the paper's 2×3
    assert figures.figure_layout("continuous", ["Hopper-v4", "Pendulum-v1"]) == (["Hopper-v4", "Pendulum-v1"], None)


def test_cartpole_axis_is_clipped_to_its_returns_and_clipped_bands_are_marked(tmp_path):
    # two seeds: t_{0.975,1} = 12.7, so the γ = 2 band runs far past 500
    means = {("CartPole-v1", "ppo", 100000, 1.0): [100.0, 300.0], ("CartPole-v1", "pgg_g1.1", 100000, 1.0): [150.0, 350.0],
             ("CartPole-v1", "pgg_g1.1", 100000, 2.0): [300.0, 499.0], ("CartPole-v1", "ppo", 200000, 1.0): [400.0, 499.0],
             ("CartPole-v1", "pgg_g1.1", 200000, 1.0): [450.0, 499.0], ("CartPole-v1", "pgg_g1.1", 200000, 2.0): [480.0, 499.0]}  # fmt: skip
    write_episodes(tmp_path / "episodes.csv", episode_rows(means))
    summary = summary_of(tmp_path / "episodes.csv")
    for fig in (figures.figure_for_variant(summary, ["CartPole-v1"], "pgg_g1.1"),
                figures.gamma_response(summary, ["CartPole-v1"], step=None)):  # fmt: skip
        ax = fig.axes[0]
        low, high = ax.get_ylim()
        assert -20 <= low and high <= 520  # 0–500 and a small margin, not −1,000 to 1,500
        edge_marks = [c for c in ax.collections if isinstance(c, matplotlib.collections.PathCollection)
                      and len(c.get_offsets()) and np.allclose(np.asarray(c.get_offsets())[:, 1], high)]  # fmt: skip
        assert edge_marks, "a band past the top of the axis must be marked"
        assert "CI runs past the axis (clipped)" in legend_labels(fig)


def line_style(fig, label: str, ax: int = 0) -> tuple[str, str]:
    """(colour as hex, marker) of the line with this label."""
    line = next(line for line in fig.axes[ax].get_lines() if line.get_label() == label)
    return matplotlib.colors.to_hex(line.get_color()), line.get_marker()


def test_one_gamma_and_one_variant_have_one_colour_in_every_figure(tmp_path):
    means = {("CartPole-v1", variant, step, gamma): [90.0 * gamma, 91.0 * gamma, 92.0 * gamma]
             for variant in ("ppo", "pgg_g1.1") for step in (100000, 200000) for gamma in (1.0, 2.0, 5.0)}  # fmt: skip
    write_episodes(tmp_path / "both.csv", episode_rows(means))
    write_episodes(tmp_path / "guided.csv", episode_rows({k: v for k, v in means.items() if k[1] == "pgg_g1.1"}))
    summary = summary_of(tmp_path / "both.csv")
    ppo_fig = figures.figure_for_variant(summary, ["CartPole-v1"], "ppo")
    pgg_fig = figures.figure_for_variant(summary, ["CartPole-v1"], "pgg_g1.1")
    for gamma in (2.0, 5.0):  # the PPO figure has no γ = 1 line: its first γ must not take γ = 1's colour
        expected = (figures.gamma_colour(gamma, "discrete"), figures.gamma_marker(gamma, "discrete"))
        assert line_style(ppo_fig, f"γ = {gamma:g}") == line_style(pgg_fig, f"γ = {gamma:g}") == expected
    assert len({line_style(pgg_fig, f"γ = {g}")[0] for g in (1, 2, 5)}) == 3
    assert figures.gamma_colour(1.05, "continuous") != figures.gamma_colour(1.0, "continuous")
    # the paper's colours in its continuous figure (its legend, read in paper_study/data/read_dropout_figure.py) ...
    paper = {1.0: (71, 42, 122), 1.1: (33, 145, 140), 1.2: (176, 221, 47)}
    for gamma, rgb in paper.items():
        ours = np.array(matplotlib.colors.to_rgb(figures.gamma_colour(gamma, "continuous"))) * 255
        assert np.abs(ours - rgb).sum() < 12
    # ... and the table's γ past it in colours of their own
    beyond = {figures.gamma_colour(g, "continuous") for g in (1.25, 1.3, 1.5)}
    assert len(beyond) == 3 and not beyond & {figures.gamma_colour(g, "continuous") for g in paper}
    beside_ppo = figures.gamma_response(summary, ["CartPole-v1"], step=None)
    alone = figures.gamma_response(summary_of(tmp_path / "guided.csv"), ["CartPole-v1"], step=None)
    name = "PGG, γ_train = 1.1"
    assert line_style(beside_ppo, name) == line_style(alone, name)  # not a colour by position in the legend
    assert line_style(beside_ppo, name)[0] == matplotlib.colors.to_hex(figures.variant_colour("pgg_g1.1"))
    assert line_style(beside_ppo, "PPO")[0] == "#000000"
    matplotlib.pyplot.close("all")


def test_the_continuous_dropout_figure_draws_the_papers_gammas_and_the_rest_apart(tmp_path, monkeypatch):
    means = {("Hopper-v4", "ppo", 200000, 1.0): [1000.0, 1100.0, 1200.0]}
    means |= {("Hopper-v4", "pgg_drop0.1", 200000, g): [900.0 + g, 950.0, 1000.0] for g in (1.0, 1.2, 1.5)}
    rows = episode_rows(means)
    for row in rows:
        row["cond_dropout"], row["train_guidance"] = (0.1 if row["variant"] == "pgg_drop0.1" else 0.0), 1.0
    write_episodes(tmp_path / "episodes.csv", rows)
    figures = {}
    monkeypatch.setattr(plots, "save_figure", lambda fig, stem, written: figures.setdefault(stem.name, fig))
    plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    labels = lambda fig: [line.get_label() for line in fig.axes[0].get_lines() if not line.get_label().startswith("_")]
    assert labels(figures["fig_continuous_pgg_drop0.1"]) == ["PPO (γ = 1)", "γ = 1", "γ = 1.2"]  # the paper's 1.0-1.2
    beyond = figures["fig_continuous_pgg_drop0.1_beyond_paper"]
    assert (
        labels(beyond) == ["PPO (γ = 1)", "γ = 1", "γ = 1.5"]
        and "beyond the paper's figure (1.5)" in beyond._suptitle.get_text()
    )
    assert line_style(beyond, "γ = 1", ax=0) == line_style(figures["fig_continuous_pgg_drop0.1"], "γ = 1", ax=0)
    assert "fig_continuous_ppo_beyond_paper" not in figures  # only where the paper's figure draws fewer γ
    # beside the paper's figure: its y-limits (Hopper 908-3162), widened to hold our means (here ~1000)
    assert figures["fig_continuous_pgg_drop0.1"].axes[0].get_ylim() == PAPER_DROPOUT_FIGURE_YLIM["Hopper-v4"]
    assert figures["fig_continuous_ppo"].axes[0].get_ylim()[1] < 1500  # the others fit their data
    matplotlib.pyplot.close("all")


def test_a_line_from_older_training_code_is_marked_in_its_panel(tmp_path):
    old = {("Hopper-v4", "ppo", 200000, 1.0): [1000.0, 1100.0, 1200.0]}
    new = {("Hopper-v4", "pgg_g1.1", 200000, 1.0): [900.0, 950.0, 1000.0]}
    write_episodes(tmp_path / "old" / "episodes.csv", episode_rows(old))
    write_episodes(tmp_path / "new" / "episodes.csv", episode_rows(new))
    provenance = tmp_path / "provenance.csv"
    header = "csv,commits,mujoco,machine,code,code_date,notes\n"
    old_row = f"{tmp_path / 'old' / 'episodes.csv'},abc1234,2.3.7,two cores,aaa0001,2026-11-22 09:22,\n"
    new_row = f"{tmp_path / 'new' / 'episodes.csv'},def5678,2.3.7,two cores,bbb0002,2026-11-29 03:53,\n"
    provenance.write_text(header + old_row + new_row)
    summary = summary_of(tmp_path / "old", tmp_path / "new", provenance=str(provenance))
    fig = figures.figure_for_variant(summary, ["Hopper-v4"], "pgg_g1.1")
    assert fig.axes[0].get_title() == "Hopper-v4 (3 seeds)\nPPO: older code (aaa0001)"
    assert figures.figure_for_variant(summary, ["Hopper-v4"], "ppo").axes[0].get_title() == "Hopper-v4 (3 seeds)"
    response = figures.gamma_response(summary, ["Hopper-v4"], step=None).axes[0].get_title()
    assert response == "Hopper-v4 at 200k steps\n3 seeds\nPPO: older code\n(aaa0001)"
    same = summary_of(tmp_path / "old", tmp_path / "new")  # no provenance: nothing to mark
    assert figures.figure_for_variant(same, ["Hopper-v4"], "pgg_g1.1").axes[0].get_title() == "Hopper-v4 (3 seeds)"
    matplotlib.pyplot.close("all")


def test_gamma_response_labels_exactly_the_swept_gammas(sweep_dir):
    fig = figures.gamma_response(summary_of(sweep_dir), ["CartPole-v1"], step=None)
    fig.canvas.draw()
    ax = fig.axes[0]
    assert ax.get_xscale() == "log"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "2"]
    assert not [t.get_text() for t in ax.get_xticklabels(minor=True) if t.get_text()]
    assert legend_labels(fig) == ["PPO", "PGG, γ_train = 1.1"]


@pytest.mark.slow
def test_learning_curves_draw_few_points_and_say_so(sweep_dir, tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    for seed in (1, 2):
        run = tmp_path / "runs" / f"CartPole-v1__pgg_g1.1__s{seed}"
        run.mkdir(parents=True)
        args = {"env_id": "CartPole-v1", "guidance": 1.1, "cond_dropout": 0.0, "seed": seed}
        (run / "args.json").write_text(json.dumps(args))
        write_checkpoint(run, args, 1024)
        writer = SummaryWriter(str(run))
        for step, value in ((512, 20.0 + seed), (1024, 40.0 + seed)):  # episodes logged at two steps only
            writer.add_scalar("charts/episodic_return", value, step)
        writer.close()
    fig = figures.learning_curves(*plots.training_curves([str(tmp_path / "runs")]))
    ax = fig.axes[0]
    line = next(line for line in ax.get_lines() if line.get_label() == "PGG, γ_train = 1.1 (n=2, no CI band)")
    assert list(line.get_ydata()) == [21.5, 41.5] and line.get_marker() == "o"
    assert line.get_color() == figures.variant_colour("pgg_g1.1")  # the variant's colour in every figure
    assert any("too few points" in t.get_text() and "only 2 points" in t.get_text() for t in ax.texts)
    matplotlib.pyplot.close(fig)
    written = generate(sweep_dir, tmp_path, runs=(str(tmp_path / "runs"),))
    assert tmp_path / "out" / "learning_curves.png" in written


# --- summaries and controls -----------------------------------------------------------------------


def test_aggregate_and_best_gamma(generated):
    sweep_dir, out, _ = generated
    best = read_csv(out / "best_gamma.csv")
    chosen = {(r["env_id"], r["variant"], r["step"]): float(r["best_eval_guidance"]) for r in best}
    assert chosen[("CartPole-v1", "pgg_g1.1", "100000")] == 1.0 and chosen[("Acrobot-v1", "pgg_g1.1", "100000")] == 2.0
    aggregate = read_csv(out / "aggregate_iqm.csv")
    row = next(
        r for r in aggregate if r["variant"] == "pgg_g1.1" and r["step"] == "200000" and r["eval_guidance"] == "2.0"
    )
    # normalised by the paper's PPO at its first and last step (CartPole 270.6 and 487.8, Acrobot −111.3 and
    # −83.6), fixed references: the sweep's other cells do not move it
    cells = {(r["env_id"], int(r["step"]), float(r["eval_guidance"])): r for r in summary_of(sweep_dir)
             if r["variant"] == "pgg_g1.1"}  # fmt: skip
    scores = []
    for env, (first, last) in {"CartPole-v1": (270.6, 487.8), "Acrobot-v1": (-111.3, -83.6)}.items():
        scores += [(float(x) - first) / (last - first) for x in cells[(env, 200000, 2.0)]["seed_means"].split(";")]
    assert float(row["iqm"]) == pytest.approx(stats.trim_mean(scores, 0.25), abs=1e-4)
    assert float(row["ci_low"]) <= float(row["iqm"]) <= float(row["ci_high"])


def test_batched_iqm_equals_scipy_trim_mean():
    rng = np.random.default_rng(0)
    samples = [rng.normal(size=(7, 5)), rng.normal(size=(7, 3))]
    expected = [stats.trim_mean(np.concatenate([s[i] for s in samples]), 0.25) for i in range(7)]
    assert aggregation.iqm_along(*samples, axis=-1) == pytest.approx(expected)


@pytest.mark.slow
def test_the_performance_profile_is_drawn_from_the_iqms_normalised_scores(sweep_dir, tmp_path):
    """Beside the IQM, rliable's performance profile: at the last step, per variant and eval γ, the
    fraction of the same normalised (env, seed) scores the IQM pools above each τ."""
    written = generate(sweep_dir, tmp_path)
    assert {
        tmp_path / "out" / "performance_profile_discrete.png",
        tmp_path / "out" / "performance_profile_discrete.pdf",
    } <= set(written)
    summary = summary_of(sweep_dir / "episodes.csv")
    scores = aggregation.normalised_scores(summary)
    profiles, step, envs = aggregation.performance_profiles(summary)
    assert step == 200000 and envs == 2 and set(profiles) == {("ppo", 1.0), ("pgg_g1.1", 1.0), ("pgg_g1.1", 2.0)}
    for (variant, gamma), (taus, profile, low, high) in profiles.items():
        pooled = np.concatenate(scores[(variant, step, gamma)])
        assert profile == pytest.approx([(pooled > tau).mean() for tau in taus])
        assert np.all(low <= profile + 1e-12) and np.all(profile <= high + 1e-12)
        iqm_row = next(
            r
            for r in aggregation.aggregate_iqm(summary)
            if (r["variant"], r["step"], r["eval_guidance"]) == (variant, step, gamma)
        )
        assert iqm_row["iqm"] == round(float(stats.trim_mean(pooled, 0.25)), 4)  # the IQM's scores, the same
    fig = figures.performance_profiles(profiles, step, envs, "discrete")
    assert [ax.get_title() for ax in fig.axes if ax.get_visible()] == ["PPO", "PGG, γ_train = 1.1"]
    matplotlib.pyplot.close(fig)


def test_the_performance_profile_agrees_with_rliables():
    """Checked once against rliable (needs pandas<3): the profile is equal, its stratified-bootstrap
    interval within one step of the profile (1/30 here: 6 tasks × 5 runs), as two RNGs allow."""
    rly = pytest.importorskip("rliable.library")
    rng = np.random.default_rng(0)
    per_task = [rng.normal(0.5, 0.3, 5) for _ in range(6)]
    taus = np.linspace(-0.5, 1.5, 41)
    profile, low, high = performance_profile(per_task, taus)
    theirs, intervals = rly.create_performance_profile({"x": np.stack(per_task, axis=1)}, taus, reps=2000)
    assert np.array_equal(profile, theirs["x"])
    assert np.abs(low - intervals["x"][0]).max() <= 1 / 30 + 1e-9
    assert np.abs(high - intervals["x"][1]).max() <= 1 / 30 + 1e-9


@pytest.mark.slow
def test_controls_table_puts_evaluation_modes_side_by_side(sweep_dir, tmp_path):
    with open(sweep_dir / "episodes.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["env_id"] == "CartPole-v1" and r["step"] == "100000"]
    uniform = [r | {"null_branch": "uniform", "return": float(r["return"]) + 10} for r in rows if r["variant"] == "ppo"]
    write_episodes(tmp_path / "uniform.csv", uniform)
    plots.generate(plots.Args(sweeps=(str(sweep_dir), str(tmp_path / "uniform.csv")), output=str(tmp_path / "out")))
    table = (tmp_path / "out" / "controls.md").read_text().splitlines()
    assert table[0] == "| env | variant | step | eval γ | sample, learned null | sample, uniform null |"
    assert table[2:] == [f"| CartPole-v1 | ppo | 100k | 1 | 271.0 ± {HALF_WIDTH:.1f} | 281.0 ± {HALF_WIDTH:.1f} |"]
    # the main tables still report the sampled, learned-null mode only
    assert (
        f"| PPO | -200.0 ± {HALF_WIDTH:.1f} | 271.0 ± {HALF_WIDTH:.1f} |"
        in (tmp_path / "out" / "table_discrete.md").read_text()
    )


# --- errors: one line, up front -------------------------------------------------------------------


@pytest.mark.parametrize(
    "setup,extra,message",
    [
        ("missing", [], "no sweep CSV"),
        ("empty", [], "is empty"),
        ("columns", [], "lacks columns"),
        ("unknown_env", [], "records no action_space for MyEnv-v0, and cannot make environment 'MyEnv-v0'"),
        ("two_kinds", [], "CartPole-v1 has discrete actions in"),
        ("random_bytes", [], "is not a CSV: byte 128 is not UTF-8 text"),
    ],
)
def test_bad_input_exits_with_one_line(tmp_path, setup, extra, message):
    target = tmp_path / "episodes.csv"
    if setup == "empty":
        target.write_text("")
    elif setup == "columns":
        target.write_text("a,b\n1,2\n")
    elif setup == "unknown_env":
        write_episodes(target, episode_rows({("MyEnv-v0", "ppo", 1000, 1.0): [1.0, 2.0]}))
    elif setup == "two_kinds":
        cell = {("CartPole-v1", "ppo", 1000, 1.0): [1.0, 2.0]}
        write_episodes(target, episode_rows(cell) + episode_rows(cell, run_suffix="b", action_space="continuous"))
    elif setup == "random_bytes":
        target.write_bytes(bytes(range(256)) * 8)
    one_error_line(run_cli(target, "--output", tmp_path / "o", *extra), message)


def test_no_paths_is_a_usage_error(tmp_path):
    proc = run_cli("--output", tmp_path / "o")
    one_error_line(proc, "no sweep given")
    assert "usage: plot_results.py SWEEP" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_missing_runs_fails_before_anything_is_written(sweep_dir, tmp_path):
    proc = run_cli(sweep_dir, "--runs", tmp_path / "no_such_runs", "--output", tmp_path / "o")
    one_error_line(proc, f"--runs: no such file or directory: {tmp_path / 'no_such_runs'}")
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_unwritable_output_is_one_line(sweep_dir, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    one_error_line(run_cli(sweep_dir, "--output", blocker / "out"), "cannot write to")


def test_invalid_choices_are_rejected_up_front(sweep_dir, tmp_path):
    with pytest.raises(plots.InputError, match="--policy must be sample or deterministic"):
        plots.validate(plots.Args(sweeps=(str(sweep_dir),), output=str(tmp_path / "o"), policy="greedy"))
    with pytest.raises(plots.InputError, match="--provenance: no such file"):
        plots.validate(
            plots.Args(sweeps=(str(sweep_dir),), output=str(tmp_path / "o"), provenance=str(tmp_path / "x.csv"))
        )


def test_learning_curves_never_count_one_seed_twice(tmp_path):
    """The same run name under two roots (two machines, two MuJoCo versions) is two runs of one
    configuration and seed: an error naming both, not one curve with twice the seeds."""
    from torch.utils.tensorboard import SummaryWriter

    for root in ("a", "b"):
        run = tmp_path / root / "CartPole-v1__ppo_pgg__g1__p0__s1"
        run.mkdir(parents=True)
        args = {"env_id": "CartPole-v1", "guidance": 1.0, "cond_dropout": 0.0, "seed": 1}
        (run / "args.json").write_text(json.dumps(args))
        write_checkpoint(run, args, 512)
        writer = SummaryWriter(str(run))
        writer.add_scalar("charts/episodic_return", 20.0, 512)
        writer.close()
    with pytest.raises(plots.InputError, match="two runs of one configuration and seed 1"):
        plots.training_curves([str(tmp_path / "a"), str(tmp_path / "b")])


def test_runs_without_episodic_returns_are_one_error_naming_where(tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    run = tmp_path / "runs" / "CartPole-v1__ppo__s1"
    run.mkdir(parents=True)
    args = {"env_id": "CartPole-v1", "guidance": 1.0, "cond_dropout": 0.0, "seed": 1}
    (run / "args.json").write_text(json.dumps(args))
    write_checkpoint(run, args, 512)
    writer = SummaryWriter(str(run))
    writer.add_scalar("losses/value_loss", 1.0, 512)  # a run that logged no episode
    writer.close()
    with pytest.raises(plots.InputError, match=f"no TensorBoard episodic returns under {tmp_path / 'runs'}"):
        plots.training_curves([str(tmp_path / "runs")])


PAPER_DROPOUT_FIGURE = ROOT.parent / "shared" / "paper" / "fig_continuous_dropout0.1.png"
from paper_study.data import read_dropout_figure as reader


@pytest.mark.skipif(
    not PAPER_DROPOUT_FIGURE.is_file(), reason="the paper's figures are in ../shared/paper, not in the repository"
)
def test_dropout_figure_reading_recovers_the_papers_ppo_table(tmp_path):
    # The figure's PPO markers are the paper's PPO table at 200k and 1M: the pixel-to-return calibration
    # must give those numbers back, to within 1% of each panel's y range.
    out = tmp_path / "readings.csv"
    reader.read_figure(reader.Args(figure=PAPER_DROPOUT_FIGURE, csv=out))
    with open(ROOT / "paper_study" / "data" / "paper_results.csv") as f:
        table = {(p["env_id"], int(p["step"])): float(p["mean"]) for p in csv.DictReader(f) if p["method"] == "ppo"}
    with open(out) as f:
        readings = list(csv.DictReader(f))
    checked = 0
    for row in readings:
        if row["line"] != "ppo" or not row["paper_figure_mean"]:
            continue  # a PPO marker under a dropout marker of the same value is not read
        _, (top, bottom), ((y1, v1), (y2, v2)) = reader.PANELS[row["env_id"]]
        y_range = abs(v2 - v1) / abs(y2 - y1) * (bottom - top)
        assert float(row["paper_figure_mean"]) == pytest.approx(
            table[(row["env_id"], int(row["step"]))], abs=0.01 * y_range
        )
        checked += 1
    assert checked >= 8
    with open(ROOT / "paper_study" / "data" / "paper_dropout_figure.csv") as f:
        assert list(csv.DictReader(f)) == readings  # the committed readings are this script's


def test_dropout_tables_set_our_cells_beside_the_readings(tmp_path):
    readings = [{"env_id": "InvertedPendulum-v4", "step": 1_000_000, "line": "pgg_drop0.1", "eval_guidance": gamma,
                 "paper_figure_mean": value} for gamma, value in ((1.0, 920.0), (1.1, None), (1.2, 985.6))]  # fmt: skip
    # seed means 920, 930, 940 -> 930.0 ± 24.8 (t(.975, 2) · 10 / √3); γ 1.2 is +40, +20, +30 on the same seeds
    drop_1, drop_12, ppo = [920.0, 930.0, 940.0], [960.0, 950.0, 970.0], [970.0, 980.0, 990.0]
    ours = {("InvertedPendulum-v4", "pgg_drop0.1", 1_000_000, 1.0): drop_1,
            ("InvertedPendulum-v4", "pgg_drop0.1", 1_000_000, 1.2): drop_12,
            ("InvertedPendulum-v4", "ppo", 1_000_000, 1.0): ppo}  # fmt: skip
    write_episodes(tmp_path / "episodes.csv", episode_rows(ours))
    summary = reader.our_summary((tmp_path / "episodes.csv",), None)
    table = reader.comparison_table(readings, summary)
    assert "| InvertedPendulum-v4 | 1M | 1 | 920.0 | 930.0 ± 24.8 | yes |" in table
    assert "| InvertedPendulum-v4 | 1M | 1.2 | 985.6 | 960.0 ± 24.8 | **no** |" in table
    assert "| InvertedPendulum-v4 | 1M | 1.1 | hidden under another marker | 940.0" not in table  # no such cell of ours
    assert "| InvertedPendulum-v4 | 1M | 1.1 | hidden under another marker | not run |  |" in table
    effects = reader.effects_table(readings, summary, {("InvertedPendulum-v4", 1_000_000): 864.7})
    welch = stats.ttest_ind(drop_1, ppo, equal_var=False).pvalue
    paired = stats.ttest_rel(drop_12, drop_1).pvalue  # one task: Holm leaves each p as it is
    assert (f"| InvertedPendulum-v4 | 980.0 ± 24.8 | 930.0 ± 24.8 | {welch:.3f} ({welch:.3f}) | 864.7 / 920.0 "
            f"| +30.0 ± 24.8 | {paired:.3f} ({paired:.3f}) | +65.6 |") in effects  # fmt: skip


# --- two sweeps of one grid (paper_study/compare_sweeps.py) -----------------------------------------

from paper_study import compare_sweeps


def test_two_sweeps_are_compared_cell_by_cell(tmp_path):
    shifted = dict(SEED_MEANS)
    shifted[("CartPole-v1", "ppo", 200000, 1.0)] = [400, 401, 402]  # +100 with a seed sd of 1: significant
    shifted[("CartPole-v1", "ppo", 100000, 1.0)] = [273, 274, 276]  # p ≈ 0.02 alone, not after Holm over 6
    write_episodes(tmp_path / "a.csv", episode_rows(SEED_MEANS))
    write_episodes(tmp_path / "b.csv", episode_rows({k: v for k, v in shifted.items() if k[0] == "CartPole-v1"},
                                                    config="mujoco=3.1.6"))  # fmt: skip
    rows = compare_sweeps.compare(compare_sweeps.cells(str(tmp_path / "b.csv")),
                                  compare_sweeps.cells(str(tmp_path / "a.csv")), "a")  # fmt: skip
    assert len(rows) == 6  # the Acrobot cells of a have no counterpart
    by_cell = {(r["env_id"], r["variant"], r["step"], r["eval_guidance"]): r for r in rows}
    moved = by_cell[("CartPole-v1", "ppo", 200000, 1.0)]
    assert moved["diff"] == pytest.approx(100) and moved["significant"] == "True"
    moderate = by_cell[("CartPole-v1", "ppo", 100000, 1.0)]
    expected_p = stats.ttest_ind([273, 274, 276], [270, 271, 272], equal_var=False).pvalue
    assert moderate["p"] == pytest.approx(expected_p, rel=1e-6) and 0.01 < expected_p < 0.05
    p_values = sorted(r["p"] for r in rows)
    assert (
        moderate["p_holm"] == pytest.approx(max(6 * p_values[0], 5 * expected_p)) and moderate["significant"] == "False"
    )
    unmoved = [r for r in by_cell.values() if r is not moved and r is not moderate]
    assert len(unmoved) == 4 and all(r["diff"] == 0 and r["significant"] == "False" for r in unmoved)
    text = compare_sweeps.report(rows, ("b", "a"), ("b.csv", "a.csv"), (0, 6))
    assert (
        "6 cells in both; **1 differ significantly**" in text and "(6 of its cells not in the other, left out)" in text
    )
    assert "| CartPole-v1 | PPO | 2 | 1 | 2 | 2 / 0 (p = 0.500) |" in text
    assert "| 200k: 401.0 ± 2.5 vs 301.0 ± 2.5 (p < 0.001) |" in text  # the final step of the grid, eval γ 1


def test_compare_sweeps_refuses_two_configurations(tmp_path):
    write_episodes(tmp_path / "a.csv", episode_rows(SEED_MEANS, config="learning_rate=0.1"))
    write_episodes(tmp_path / "b.csv", episode_rows(SEED_MEANS, config="mujoco=3.1.6"))
    with pytest.raises(plots.InputError, match=r"'(\S+) learning_rate=0.1' in one sweep and '\1 mujoco=3.1.6'"):
        compare_sweeps.compare(
            compare_sweeps.cells(str(tmp_path / "a.csv")), compare_sweeps.cells(str(tmp_path / "b.csv")), "b"
        )


def test_compare_sweeps_errors_are_one_line(tmp_path, monkeypatch, capsys):
    write_episodes(
        tmp_path / "cartpole.csv", episode_rows({k: v for k, v in SEED_MEANS.items() if k[0] == "CartPole-v1"})
    )
    write_episodes(
        tmp_path / "acrobot.csv", episode_rows({k: v for k, v in SEED_MEANS.items() if k[0] == "Acrobot-v1"})
    )
    two_configs = episode_rows(SEED_MEANS, config="learning_rate=0.1") + episode_rows(
        SEED_MEANS, config="learning_rate=0.2", run_suffix="b"
    )
    write_episodes(tmp_path / "two_configs.csv", two_configs)
    for pair, message in [(("cartpole.csv", "acrobot.csv"), "no cell (env, variant, step, eval γ) in common"),
                          (("two_configs.csv", "cartpole.csv"), "2 configurations of ppo on Acrobot-v1"),
                          (("missing.csv", "cartpole.csv"), "no sweep CSV at")]:  # fmt: skip
        monkeypatch.setattr(sys, "argv", ["compare_sweeps.py", *(str(tmp_path / p) for p in pair)])
        with pytest.raises(SystemExit) as exit_info:
            compare_sweeps.main()
        err = capsys.readouterr().err
        assert exit_info.value.code == 2
        assert err.count("\n") == 1 and err.startswith("error: ") and message in err, err


@pytest.mark.slow
def test_a_replot_into_the_same_folder_drops_the_last_plots_learning_curves(tmp_path):
    """`plot_results.py A --runs R --output X`, then `plot_results.py B --output X`: the curves of A's runs
    (here of a task B does not hold) are not B's, so the rerun removes them and its outputs.txt does not
    list them; a file no run listed (committed curves, before any manifest) stays."""
    write_episodes(tmp_path / "a.csv", episode_rows({("CartPole-v1", "pgg_g1.1", 2048, 1.0): [20, 21, 22]}))
    write_episodes(tmp_path / "b.csv", episode_rows({("Acrobot-v1", "ppo", 100000, 1.0): [-90, -89, -88]}))
    write_run(tmp_path / "runs", "CartPole-v1__pgg_g1.1__s1", 1, 4096, checkpoints=(2048, 4096))
    out = tmp_path / "out"
    first = plots.generate(
        plots.Args(sweeps=(str(tmp_path / "a.csv"),), runs=(str(tmp_path / "runs"),), output=str(out))
    )
    assert {out / "learning_curves.png", out / "learning_curves.pdf"} <= set(first)
    second = plots.generate(plots.Args(sweeps=(str(tmp_path / "b.csv"),), output=str(out)))
    assert not (out / "learning_curves.png").exists() and not (out / "learning_curves.pdf").exists()
    listed = set(read_manifest(out))
    assert listed == {p.name for p in second} - {"outputs.txt"} and not any("learning_curves" in n for n in listed)
    (out / "outputs.txt").unlink()  # as in a fresh clone of results/, whose curves no manifest lists
    (out / "learning_curves.png").write_bytes(b"committed, drawn from runs that are not committed")
    plots.generate(plots.Args(sweeps=(str(tmp_path / "b.csv"),), output=str(out)))
    assert (out / "learning_curves.png").read_bytes() == b"committed, drawn from runs that are not committed"


@pytest.mark.slow
def test_checkpoint_marks_under_1k_or_between_thousands_are_labelled_exactly(tmp_path):
    """Marks of 512 and 2,048 steps were "0k" and "2k" (two marks could share a label); whole thousands
    and millions keep the paper's 100k and 1M."""
    from paper_study.agreement import step_label

    assert [step_label(s) for s in (512, 2048, 100_000, 500_000, 1_000_000, 1_500_000)] == [
        "512", "2,048", "100k", "500k", "1M", "1500k"]  # fmt: skip
    marks = {("CartPole-v1", "ppo", step, 1.0): [20, 21, 22] for step in (512, 1024)}
    write_episodes(tmp_path / "a.csv", episode_rows(marks))
    plots.generate(plots.Args(sweeps=(str(tmp_path / "a.csv"),), output=str(tmp_path / "out")))
    table = (tmp_path / "out" / "table_discrete.md").read_text()
    assert "| **512 Steps** |" in table and "| **1,024 Steps** |" in table and "0k Steps" not in table


# --- one reader of episodes.csv --------------------------------------------------------------------


@pytest.mark.slow
def test_the_paper_study_reads_episodes_without_plot_results(tmp_path):
    """The paper study's readers import pgg_utils.episodes (and paper_study.summary), not the top-level
    plot_results: each runs with plot_results made unimportable."""
    code = ("import sys; sys.modules['plot_results'] = None; sys.path.insert(0, '.'); "
            "import paper_study.compare_sweeps, paper_study.heldout_gamma, paper_study.selection, "
            "beyond.bc_train_pilot, paper_study.summary; sys.path.insert(0, 'paper_study/data'); "
            "import read_dropout_figure")  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


def test_the_sweep_and_the_tables_share_one_per_seed_mean(tmp_path):
    """The sweep's summary ordered seeds as text ("10" before "2"), the tables as numbers: both now take
    episodes.seed_means (through episodes.summarise), so one cell's seed_means reads the same in summary.csv and in
    the tables, and the held-out selection's per-seed means are the same numbers."""
    from paper_study import selection
    from pgg_utils import sweep as engine

    rows = [r | {"seed": seed, "run": f"CartPole-v1__ppo__s{seed}"}
            for seed in (2, 10) for r in episode_rows({("CartPole-v1", "ppo", 100000, 1.0): [20.0 * seed]})]  # fmt: skip
    write_episodes(tmp_path / "episodes.csv", rows)
    (table_cell,) = summary_of(tmp_path / "episodes.csv")
    (sweep_cell,) = engine.summary_rows([{k: str(v) for k, v in r.items()} for r in rows])
    assert table_cell["seed_means"] == sweep_cell["seed_means"] == "40.0000;200.0000"
    (group,) = selection.by_gamma(plots.read_episodes([tmp_path / "episodes.csv"])).values()
    assert group == {1.0: {2: 40.0, 10: 200.0}}


def test_every_reader_of_episodes_refuses_a_cut_file(tmp_path):
    """A cell short of episodes (a cut file) is refused in one line by each reader: plot_results, the
    held-out γ, the comparison of two sweeps and the cloning pilot, which read it as whole before."""
    from conftest import one_line_error

    from beyond import bc_train_pilot
    from paper_study import compare_sweeps, heldout_gamma

    rows = episode_rows(SEED_MEANS)
    write_episodes(tmp_path / "cut" / "episodes.csv", rows[:-1])
    (tmp_path / "runs").mkdir()
    cut = str(tmp_path / "cut" / "episodes.csv")
    for module, flags in [(plots, [cut, "--output", str(tmp_path / "o")]),
                          (heldout_gamma, [cut, cut, "--output", str(tmp_path / "h")]),
                          (compare_sweeps, [cut, cut]),
                          (bc_train_pilot, [str(tmp_path / "runs"), cut])]:  # fmt: skip
        line = one_line_error(run_main(module, *flags))  # each command's main, in this process
        assert "1 cell(s) hold fewer episodes than the other cells' 2" in line, (module.__name__, line)


# --- partial inputs, damaged events, two writers: refused or named, never drawn as whole -------------


def test_a_cell_with_fewer_episodes_than_the_others_is_refused(sweep_dir, tmp_path):
    """A file cut inside a cell (or one episode row deleted) is no sweep's output: one line, exit 2."""
    lines = (sweep_dir / "episodes.csv").read_text().splitlines(keepends=True)
    (sweep_dir / "episodes.csv").write_text("".join(lines[:-1]))  # the last cell loses an episode
    one_error_line(
        run_cli(sweep_dir, "--output", tmp_path / "o"), "1 cell(s) hold fewer episodes than the other cells' 2"
    )


@pytest.mark.slow
def test_cells_with_fewer_seeds_than_their_siblings_are_named(sweep_dir, tmp_path):
    """A file cut at a cell boundary loses the last run's later cells: they hold fewer seeds than the
    other cells of their configuration, and say so in the tables and in a printed line."""
    rows = episode_rows(SEED_MEANS)
    cut = [r for r in rows if not (r["run"] == "Acrobot-v1__pgg_g1.1__s3" and r["step"] == 200000)]
    write_episodes(sweep_dir / "episodes.csv", cut)
    proc = run_cli(sweep_dir, "--output", tmp_path / "o")
    assert proc.returncode == 0, proc.stderr
    assert "note: 2 cell(s) hold fewer seeds than the other cells of their configuration" in proc.stderr
    assert "Acrobot-v1 pgg_g1.1 at step 200000, eval γ 1 (2 of 3 seeds)" in proc.stderr
    table = (tmp_path / "o" / "table_discrete.md").read_text()
    assert "| -86.5 ± 6.4 (2 of 3 seeds) |" in table and "| -83.5 ± 6.4 (2 of 3 seeds) |" in table
    assert "$-86.5 \\pm 6.4$ (2 of 3 seeds)" in (tmp_path / "o" / "table_discrete.tex").read_text()


@pytest.mark.slow
def test_an_episodes_csv_that_differs_from_its_sweeps_record_is_refused(sweep_dir, tmp_path):
    """The sweep records what it wrote (written.csv: rows and sha256): a file cut at any line, even at a
    cell boundary that leaves every cell whole, is refused in one line."""
    path = sweep_dir / "episodes.csv"
    write_record(sweep_dir, {"episodes.csv": len(read_csv(path))}, "eval_gamma_sweep.py")
    assert run_cli(sweep_dir, "--output", tmp_path / "o").returncode == 0
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[: 1 + 2 * 3 * 11]))  # the first 11 cells' 3 seeds × 2 episodes: only the 12th gone
    one_error_line(run_cli(sweep_dir, "--output", tmp_path / "o"),
                   f"{path} is not the file its eval_gamma_sweep.py wrote: it holds 66 rows, "
                   f"{sweep_dir / 'written.csv'} records 72")  # fmt: skip


@pytest.mark.slow
def test_a_second_writer_into_one_output_folder_is_refused(sweep_dir, tmp_path):
    """Two plot_results.py into one --output would leave one sweep's tables beside the other's figures."""
    out = tmp_path / "o"
    out.mkdir()
    lock = lock_directory(out, "a test")  # as a plot_results.py at work in it holds it
    try:
        proc = run_cli(sweep_dir, "--output", out)
    finally:
        lock.close()
    one_error_line(proc, f"{out} is in use by another process writing into it (pid {os.getpid()}); wait for it")
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
    assert run_cli(sweep_dir, "--output", out).returncode == 0  # the lock free


def write_checkpoint(run: Path, args: dict, step: int) -> None:
    """A minimal readable checkpoint of a run's `args` at `step`: what the learning curves read of a run."""
    import torch

    ckpt = {"format_version": 2, "script": "ppo_pgg_discrete", "action_space": "discrete", "env_id": args["env_id"],
            "step_mark": step, "global_step": step, "args": args, "model": {}}  # fmt: skip
    (run / "checkpoints").mkdir(parents=True, exist_ok=True)
    torch.save(ckpt, run / "checkpoints" / f"step_{step:09d}.pt")


def write_run(root, name: str, seed: int, events_end: int, total: int = 4096, checkpoints=()) -> None:
    from torch.utils.tensorboard import SummaryWriter

    run = root / name
    (run / "checkpoints").mkdir(parents=True)
    args = {"env_id": "CartPole-v1", "guidance": 1.1, "cond_dropout": 0.0, "seed": seed, "total_timesteps": total}
    (run / "args.json").write_text(json.dumps(args))
    for step in checkpoints:
        write_checkpoint(run, args, step)
    writer = SummaryWriter(str(run))
    for step in range(512, events_end + 1, 512):
        writer.add_scalar("charts/episodic_return", 20.0 + seed, step)
        writer.add_scalar("losses/value_loss", 1.0, step)
    writer.close()


@pytest.mark.slow
def test_runs_with_damaged_short_or_missing_events_are_left_out_and_named(sweep_dir, tmp_path):
    """A run's curve is drawn only where its events reach its total_timesteps: events of random bytes,
    events cut short of the run's checkpoints, and an unfinished run are each named, not drawn."""
    root = tmp_path / "runs"
    write_run(root, "CartPole-v1__pgg_g1.1__s1", 1, 4096, checkpoints=(2048, 4096))
    write_run(root, "CartPole-v1__pgg_g1.1__s2", 2, 4096, checkpoints=(2048, 4096))
    (events,) = (root / "CartPole-v1__pgg_g1.1__s2").glob("events.out.tfevents.*")
    events.write_bytes(np.random.default_rng(0).bytes(events.stat().st_size))  # damaged beyond reading
    write_run(root, "CartPole-v1__pgg_g1.1__s3", 3, 1024, checkpoints=(2048, 4096))  # cut: events end early
    write_run(root, "CartPole-v1__pgg_g1.1__s4", 4, 2048, checkpoints=(2048,))  # unfinished: stopped at 2048
    curves, left_out = plots.training_curves([str(root)])
    assert [len(seeds) for seeds in curves.values()] == [1]  # s1 alone is whole
    assert [(run.name, why) for _, run, why in left_out] == [
        ("CartPole-v1__pgg_g1.1__s2", "its TensorBoard events hold no episodic return (missing or damaged)"),
        ("CartPole-v1__pgg_g1.1__s3", "its events end at step 1,024, its checkpoints at 4,096 (cut or damaged)"),
        ("CartPole-v1__pgg_g1.1__s4", "its events end at step 2,048 of its 4,096 (unfinished)"),
    ]
    fig = figures.learning_curves(curves, left_out)
    assert legend_labels_of_axes(fig) == ["PGG, γ_train = 1.1 (n=1, no CI band)"]
    assert any("left out, not whole" in t.get_text() and "CartPole-v1__pgg_g1.1__s3: its events end at step 1,024"
               in t.get_text() for t in fig.axes[0].texts)  # fmt: skip
    matplotlib.pyplot.close(fig)
    proc = run_cli(sweep_dir, "--runs", root, "--output", tmp_path / "o")
    assert proc.returncode == 0, proc.stderr
    assert (
        f"note: the learning curves leave out {root / 'CartPole-v1__pgg_g1.1__s2'}: its TensorBoard events"
        in proc.stderr
    )
    for run in ("s1", "s2", "s3"):
        (root / f"CartPole-v1__pgg_g1.1__{run}").rename(tmp_path / run)  # s4 alone, unfinished
    one_error_line(run_cli(sweep_dir, "--runs", root, "--output", tmp_path / "o"),
                   f"no TensorBoard episodic returns under {root} of a whole run: {root / 'CartPole-v1__pgg_g1.1__s4'}: "
                   "its events end at step 2,048 of its 4,096 (unfinished)")  # fmt: skip


def legend_labels_of_axes(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]


@pytest.mark.slow
def test_long_panel_titles_are_broken_rather_than_overlap(tmp_path):
    """Side-by-side panels of long task names with their notes would overlap: their titles are broken
    onto two lines before the notes; a figure whose titles fit draws as before."""
    envs = ("InvertedDoublePendulum-v4", "HumanoidStandup-v4", "HalfCheetah-v4")
    cells = {(env, "ppo", step, 1.0): [100.0, 101.0, 102.0] for env in envs for step in (100000, 200000)}
    write_episodes(tmp_path / "a.csv", episode_rows(cells, config="mujoco=3.1.6", action_space="continuous"))
    summary = summary_of(tmp_path / "a.csv")
    fig = figures.figure_for_variant(summary, list(envs), "ppo")
    figures.render(fig)  # what every figure goes through on its way to a file
    assert fig.axes[0].get_title() == "InvertedDoublePendulum-v4\n(3 seeds, MuJoCo 3.1.6)"
    fig = figures.figure_for_variant(summary, list(envs), "ppo")
    figures.separate_titles(fig)
    fig.draw_without_rendering()  # laid out as when it is saved
    renderer = fig.canvas.get_renderer()
    boxes = [ax.title.get_window_extent(renderer) for ax in fig.axes if ax.get_visible()]
    assert not any(a.overlaps(b) for a, b in itertools.combinations(boxes, 2))
    matplotlib.pyplot.close(fig)
    short = figures.figure_for_variant(summary_of(tmp_path / "a.csv"), ["HalfCheetah-v4"], "ppo")
    figures.render(short)
    assert short.axes[0].get_title() == "HalfCheetah-v4 (3 seeds, MuJoCo 3.1.6)"


@pytest.mark.slow
def test_a_forks_runs_are_named_by_their_script_in_every_output_whatever_else_the_sweep_holds(tmp_path):
    """A sweep of a fork's runs alone: every table row, best_gamma and aggregate_iqm names the fork's script, as they
    do beside the original's runs (today's main labelled them "pgg_g1.1" and "PPO", the original's names); and two
    configurations of one fork, told apart by an argument, both name it too."""
    write_episodes(tmp_path / "sweep" / "episodes.csv", episode_rows(SEED_MEANS, config="script=ppo_fork.py"))
    generate(tmp_path / "sweep", tmp_path)
    out = tmp_path / "out"
    methods = [line.split(" | ")[0] for line in (out / "table_discrete.md").read_text().splitlines()
               if line.startswith("| ") and not line.startswith(("| Method", "| **", "|   γ"))]  # fmt: skip
    assert methods == ["| PPO [script=ppo_fork.py]", "| pgg_g1.1 [script=ppo_fork.py]"] * 2
    for table in ("best_gamma.csv", "aggregate_iqm.csv"):
        assert {row["variant"] for row in read_csv(out / table)} == {"ppo [script=ppo_fork.py]",
                                                                    "pgg_g1.1 [script=ppo_fork.py]"}  # fmt: skip
    from paper_study.summary import config_labels

    two = {("CartPole-v1", "ppo", f"ppo script=ppo_fork.py learning_rate={rate}", 1.0, 0.0):
           ({"script": "ppo_fork.py", "learning_rate": rate}, {"sweep/episodes.csv"}) for rate in ("0.001", "0.002")}  # fmt: skip
    assert sorted(config_labels(two).values()) == [
        f"learning_rate={rate} script=ppo_fork.py" for rate in ("0.001", "0.002")
    ]
