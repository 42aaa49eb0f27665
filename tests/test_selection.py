"""Held-out selection of the eval γ (paper_study.selection, paper_study/heldout_gamma.py) on synthetic sweeps
whose answer is known: where γ changes nothing the fresh gain is 0 and the selection bias is the expected
maximum of the noise; where one γ is truly better it is selected and keeps its gain on fresh episodes."""

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import one_line_error, run_main, run_script
from scipy import integrate, stats

from paper_study import heldout_gamma
from paper_study.selection import INCOMPLETE, SELECTED_BASELINE, TESTED, held_out, summary_by_env
from pgg_utils.files import InputError, read_csv, write_csv_atomic

GAMMAS = (1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.5)  # the paper's continuous sweep: 8 values
SEEDS, EPISODES, SD = 5, 50, 10.0
COLUMNS = ["env_id", "variant", "config", "run", "seed", "train_guidance", "cond_dropout", "step", "eval_guidance",
           "policy", "null_branch", "episode", "episode_seed", "return", "action_space"]  # fmt: skip


def sweep(rng, steps, eval_seed: int, true_mean=lambda gamma, step: 100.0, gammas=GAMMAS, seeds=SEEDS,
          episodes=EPISODES) -> list[dict]:  # fmt: skip
    """Episode rows of a CartPole sweep, one group per step: returns ~ N(true_mean(γ, step), SD), iid."""
    rows = []
    for step in steps:
        for seed in range(1, seeds + 1):
            for gamma in gammas:
                returns = rng.normal(true_mean(gamma, step), SD, episodes)
                rows += [{"env_id": "CartPole-v1", "variant": "pgg_g1.1", "config": "pgg_g1.1", "seed": seed,
                          "run": f"CartPole-v1__pgg_g1.1__s{seed}", "train_guidance": 1.1, "cond_dropout": 0.0,
                          "step": step, "eval_guidance": gamma, "policy": "sample", "null_branch": "learned",
                          "episode": k, "episode_seed": eval_seed + k, "return": float(returns[k]),
                          "action_space": "discrete"} for k in range(episodes)]  # fmt: skip
    return rows


def expected_max_of_normals(k: int) -> float:
    """E[max of k iid standard normals] = ∫ x · k φ(x) Φ(x)^(k−1) dx."""
    value, _ = integrate.quad(lambda x: x * k * stats.norm.pdf(x) * stats.norm.cdf(x) ** (k - 1), -12, 12)
    return value


@pytest.mark.slow
def test_where_gamma_does_nothing_the_fresh_gain_is_zero_and_the_bias_is_the_expected_max_of_the_noise():
    rng = np.random.default_rng(0)
    steps = range(1000, 121_000, 1000)  # 120 groups
    rows, unmatched = held_out(sweep(rng, steps, 10_000), sweep(rng, steps, 20_000))
    assert unmatched == [] and len(rows) == 120 and not [r for r in rows if r["status"] == INCOMPLETE]
    cell_sd = SD / math.sqrt(SEEDS * EPISODES)  # the sd of a cell's mean over seeds of per-seed means
    expected_bias = cell_sd * expected_max_of_normals(len(GAMMAS))
    monte_carlo = rng.standard_normal((200_000, len(GAMMAS))).max(1).mean() * cell_sd
    assert expected_bias == pytest.approx(monte_carlo, abs=0.01)
    bias = np.array([r["selection_bias"] for r in rows])
    assert abs(bias.mean() - expected_bias) < 4 * bias.std(ddof=1) / math.sqrt(len(bias))
    # best_gamma's in-sample gain over γ = 1 is that same inflation, where nothing is there to find
    in_sample = np.array([r["selection_gain"] for r in rows])
    assert abs(in_sample.mean() - expected_bias) < 4 * in_sample.std(ddof=1) / math.sqrt(len(in_sample))
    tested = [r for r in rows if r["status"] == TESTED]
    gain = np.array([r["fresh_gain"] for r in tested])
    assert abs(gain.mean()) < 4 * gain.std(ddof=1) / math.sqrt(len(gain))
    assert sum(r["significant"] == "True" for r in tested) <= 1  # Holm: family-wise 5%
    baseline = [r for r in rows if r["status"] == SELECTED_BASELINE]
    assert 5 <= len(baseline) <= 30  # γ = 1 wins about 1 in 8
    assert all(r["fresh_gain"] == 0 and math.isnan(r["p"]) for r in baseline)
    (summary,) = summary_by_env(rows)
    assert summary["selected_baseline"] == len(baseline) and summary["selected_other"] == len(tested)
    assert summary["median_fresh_gain"] == pytest.approx(np.median(gain))


def test_a_truly_better_gamma_is_selected_and_keeps_its_gain_on_fresh_episodes():
    rng = np.random.default_rng(1)
    gammas = (1.0, 1.5, 2.0, 5.0, 10.0, 20.0)

    def better(gamma, step):
        return 110.0 if gamma == 2.0 else 100.0

    rows, _ = held_out(*(sweep(rng, range(1, 11), eval_seed, better, gammas) for eval_seed in (10_000, 20_000)))
    assert {r["selected_gamma"] for r in rows} == {2.0} and {r["status"] for r in rows} == {TESTED}
    gain = np.array([r["fresh_gain"] for r in rows])
    assert abs(gain.mean() - 10) < 1 and all(r["significant"] == "True" for r in rows)
    assert abs(np.mean([r["selection_bias"] for r in rows])) < 1  # no winner's curse where the winner is clear
    (summary,) = summary_by_env(rows)
    assert summary["fresh_above"] == summary["fresh_above_significant"] == 10


def test_gamma_1_wins_ties_and_is_counted_apart_with_no_test():
    flat = [r | {"return": 200.0} for r in sweep(np.random.default_rng(2), [1], 10_000, episodes=3)]
    fresh = [r | {"episode_seed": r["episode_seed"] + 10_000} for r in flat]
    (row,), _ = held_out(flat, fresh)
    assert row["status"] == SELECTED_BASELINE and row["selected_gamma"] == 1.0 and row["fresh_gain"] == 0
    assert row["significant"] == "n/a" and summary_by_env([row])[0]["selected_baseline"] == 1


def test_the_selection_and_the_fresh_sweep_must_be_of_the_same_checkpoints_and_every_seed():
    rng = np.random.default_rng(3)
    selection, fresh = sweep(rng, [1], 10_000, episodes=2), sweep(rng, [1], 20_000, episodes=2)
    with pytest.raises(InputError, match="is run CartPole-v1__pgg_g1.1__s1 in the selection sweep and other"):
        held_out(selection, [r | {"run": "other"} if r["seed"] == 1 else r for r in fresh])
    with pytest.raises(InputError, match="lacks seeds 5 at γ 1.5 of pgg_g1.1 on CartPole-v1 at step 1"):
        held_out([r for r in selection if (r["seed"], r["eval_guidance"]) != (5, 1.5)], fresh)
    with pytest.raises(InputError, match="the two sweeps have no group"):
        held_out(selection, [r | {"step": 2} for r in fresh])


def write_sweep(path, rows) -> str:
    write_csv_atomic(path, COLUMNS, rows)
    return str(path)


def test_overlapping_episode_seeds_are_refused_in_one_line(tmp_path):
    rng = np.random.default_rng(4)
    selection = write_sweep(tmp_path / "sel.csv", sweep(rng, [1000], 10_000, episodes=5))
    fresh = write_sweep(tmp_path / "fresh.csv", sweep(rng, [1000], 10_003, episodes=5))
    out = str(tmp_path / "out")
    line = one_line_error(run_main(heldout_gamma, selection, fresh, "--output", out))  # its main, in this process
    assert line == ("error: 2 episode seeds (10003–10004) of run CartPole-v1__pgg_g1.1__s1 at step 1000 are in both "
                    "sweeps; sweep the fresh episodes with another --eval-seed (e.g. 20000)")  # fmt: skip
    line = one_line_error(run_main(heldout_gamma, selection, selection, "--output", out))
    assert line.startswith("error: 5 episode seeds (10000–10004)")
    assert not Path(out).exists()


@pytest.mark.slow
def test_groups_the_fresh_sweep_lacks_are_reported_not_dropped(tmp_path):
    rng = np.random.default_rng(5)

    def better(gamma, step):
        return 150.0 if gamma == 1.5 else 100.0

    selection = sweep(rng, [1000, 2000, 3000], 10_000, better, episodes=5)
    gaps = {(3000, 1.5, 2), (3000, 1.5, 4)}  # two seeds of the selected γ at 3k; all of 2k
    fresh = [r for r in sweep(rng, [1000, 2000, 3000, 4000], 20_000, better, episodes=5)
             if r["step"] != 2000 and (r["step"], r["eval_guidance"], r["seed"]) not in gaps]  # fmt: skip
    out = tmp_path / "out"
    proc = run_script("paper_study/heldout_gamma.py", write_sweep(tmp_path / "sel.csv", selection),
                      write_sweep(tmp_path / "fresh.csv", fresh), "--output", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [str(out / "heldout_gamma.csv"), str(out / "heldout_gamma.md")]
    rows = {int(r["step"]): r for r in read_csv(out / "heldout_gamma.csv")}
    assert sorted(rows) == [1000, 2000, 3000]
    assert rows[1000]["status"] == TESTED and rows[1000]["selected_gamma"] == "1.5"
    assert rows[2000]["status"] == rows[3000]["status"] == INCOMPLETE
    assert rows[2000]["missing"] == "the fresh sweep has no episodes of this group"
    assert rows[3000]["missing"] == "the fresh sweep lacks γ 1.5 for seeds 2, 4"
    assert rows[2000]["selected_gamma"] == "1.5" and rows[2000]["fresh_gain"] == "nan"
    text = (out / "heldout_gamma.md").read_text()
    assert "**Groups that cannot be answered (2)**" in text
    assert "- CartPole-v1, PGG, γ_train = 1.1, 2k: the fresh sweep has no episodes of this group" in text
    assert "the selection sweep lacks (1), left out:\n\n- CartPole-v1, pgg_g1.1, 4k" in text
    assert "| CartPole-v1 | PGG, γ_train = 1.1 | 3 | 0 | 1 | 1 | 1 |" in text
