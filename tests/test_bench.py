import csv
import itertools
import json
import subprocess
import sys
import threading

import numpy as np
import pytest
import torch
from conftest import ROOT

import ppo_pgg_discrete as pgg
from benchmarks import bench_speed, compare_cleanrl
from pgg_utils import checkpoints, runs


def tiny_run(guidance: float, seed: int = 1) -> pgg.Args:
    return pgg.Args(total_timesteps=3 * 4 * 32, num_steps=32, guidance=guidance, seed=seed)


def test_interleaved_runs_take_strict_turns_one_iteration_at_a_time(monkeypatch):
    """The PGG overhead is measured on two runs that hand over at every rollout: if both ran at once,
    or one ran several iterations in a row, its pairs would no longer be seconds-free."""
    workers = []
    compute_gae = pgg.compute_gae

    def spy(*args, **kwargs):  # called once per iteration, inside the run's turn
        workers.append(threading.get_ident())
        return compute_gae(*args, **kwargs)

    monkeypatch.setattr(pgg, "compute_gae", spy)
    timed = bench_speed.interleaved_training(pgg, [tiny_run(1.0), tiny_run(1.1)])

    assert len(workers) == 6 and len(set(workers)) == 2
    assert all(a != b for a, b in itertools.pairwise(workers))  # A, B, A, B, A, B
    for run in timed:
        assert len(run["turns"]) == 4  # the setup, then one per iteration
        assert len(run["updates"]) == 3 and all(u > 0 for u in run["updates"])
    assert pgg.collect_rollout.__name__ == "collect_rollout" and pgg.ppo_update.__name__ == "ppo_update"


def test_a_failing_interleaved_run_raises_instead_of_leaving_the_other_waiting():
    failing = tiny_run(1.1)
    failing.env_id = "NoSuchEnv-v0"
    with pytest.raises(Exception, match="NoSuchEnv"):
        bench_speed.interleaved_training(pgg, [tiny_run(1.0), failing])
    assert pgg.collect_rollout.__name__ == "collect_rollout"


def test_overhead_interval_contains_the_ratio_of_sums():
    base = np.array([1.0, 2.0, 3.0, 4.0])
    text = bench_speed.overhead_with_interval(base, base * 1.1)
    assert text == "+10.0% (+10.0% to +10.0%)"


@pytest.mark.slow
def test_sweep_checkpoints_are_matched_to_their_env_and_bad_ones_are_one_line_of_error(tmp_path):
    args = tiny_run(1.1)
    args.output_dir, args.checkpoint_interval = str(tmp_path), 10**9
    runs.train_in_process(pgg, args)
    (checkpoint,) = tmp_path.rglob("step_*.pt")
    assert bench_speed.checkpoints_by_env([str(checkpoint)]) == {"CartPole-v1": checkpoint}

    not_a_checkpoint = tmp_path / "notes.txt"
    not_a_checkpoint.write_text("not a checkpoint")
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_speed", "--sweep-checkpoints", str(not_a_checkpoint)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert out.returncode != 0
    assert out.stderr.startswith("error: --sweep-checkpoints") and len(out.stderr.strip().splitlines()) == 1


def save_parity_run(folder, impl: str, seed: int, episodes, steps_trained: int, total: int = 1000):
    """A run of compare_cleanrl as it saves one: (step, return) rows in a CSV and its metadata beside it."""
    run = compare_cleanrl.Run(impl, seed, folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = {
        "total_timesteps": total, "steps_trained": steps_trained, "wall_time_s": 2.0, "sps_reported": 600.0,
        "script": "ppo_pgg_discrete.py" if impl == "ours" else "ppo.py", "script_sha256": "0" * 64, "cpu": "test cpu",
        "stack": {"python": "3.11", "torch": "2.13.0", "numpy": "1.26.4", "gymnasium": "0.29.1", "mujoco": None},
    }  # fmt: skip
    compare_cleanrl.write_atomic(run.meta, json.dumps(meta))
    compare_cleanrl.write_atomic(run.csv, "step,return\n" + "".join(f"{s},{r}\n" for s, r in episodes))


def test_parity_curve_bins_episodes_by_their_end_and_carries_over_empty_bins():
    episodes = np.array([(10, 1.0), (25, 3.0), (60, 5.0), (100, 7.0), (110, 1e6)])  # 110: past the range
    np.testing.assert_array_equal(compare_cleanrl.binned_curve(episodes, end=100, bins=4), [2, 2, 5, 7])
    leading_gap = compare_cleanrl.binned_curve(np.array([(60, 5.0)]), end=100, bins=4)
    np.testing.assert_array_equal(leading_gap, [np.nan, np.nan, 5, 5])
    assert compare_cleanrl.run_scores(episodes, end=100) == (4.0, 7.0)  # whole range; (90, 100]

    mean, half = compare_cleanrl.mean_ci(np.array([[0.0, np.nan], [2.0, 4.0]]))
    np.testing.assert_allclose(mean, [1.0, 4.0])
    assert half[0] == pytest.approx(12.706, abs=1e-3) and np.isnan(half[1])  # t_0.975,1 * s / sqrt(2); one value


def test_parity_analysis_cuts_at_the_shorter_run_and_welch_tells_a_shift(tmp_path):
    """CleanRL floors its iterations and we round up: scores count only episodes both could have had."""
    for seed in (1, 2, 3):
        episodes = [(100, 10 + seed), (500, 20 + seed), (950, 30 + seed), (1000, 40 + seed)]
        save_parity_run(tmp_path / "same" / "CartPole-v1", "ours", seed, episodes + [(1010, 1e6)], steps_trained=1024)
        save_parity_run(tmp_path / "same" / "CartPole-v1", "cleanrl", seed, episodes, steps_trained=1000)
        shifted = episodes[:2] + [(step, r - 100) for step, r in episodes[2:]]
        save_parity_run(tmp_path / "shift" / "CartPole-v1", "ours", seed, shifted, steps_trained=1024)
        save_parity_run(tmp_path / "shift" / "CartPole-v1", "cleanrl", seed, episodes, steps_trained=1000)

    same = compare_cleanrl.compute("CartPole-v1", tmp_path / "same" / "CartPole-v1")
    assert same.end == 1000
    np.testing.assert_allclose(same.scores["ours"], [[26, 36], [27, 37], [28, 38]])  # 1010's 1e6 is left out
    np.testing.assert_allclose(same.scores["cleanrl"], same.scores["ours"])
    summary = compare_cleanrl.analyse("CartPole-v1", tmp_path / "same")
    assert "no significant difference at α=0.05" in summary and "490.04 ± 6.12" in summary
    assert (tmp_path / "same" / "CartPole-v1.png").stat().st_size > 0
    assert (tmp_path / "same" / "CartPole-v1_summary.md").read_text() == summary

    shift = compare_cleanrl.compute("CartPole-v1", tmp_path / "shift" / "CartPole-v1")
    verdict = compare_cleanrl.verdict(shift.scores, shift.p_values)
    assert verdict.startswith("significant difference at α=0.05 in ")
    assert "mean return over its last tenth (ours lower, p = " in verdict


def test_parity_rerun_trains_only_the_runs_not_saved(tmp_path, monkeypatch):
    folder = tmp_path / "CartPole-v1"
    save_parity_run(folder, "ours", 1, [(100, 20.0)], steps_trained=1024)
    trained = []
    monkeypatch.setattr(compare_cleanrl, "train_one", lambda plan, run, scratch: trained.append(run.name) or run.name)
    plan = compare_cleanrl.Plan("CartPole-v1", 1000, folder, scripts={}, stacks={})
    compare_cleanrl.train_missing(plan, seeds=2, workers=1)
    assert sorted(trained) == ["cleanrl_s1", "cleanrl_s2", "ours_s2"]

    args = compare_cleanrl.Args(env_id="CartPole-v1", total_timesteps=2000, output=str(tmp_path))
    with pytest.raises(compare_cleanrl.CompareError, match="holds runs of 1,000 steps, not 2,000"):
        compare_cleanrl.make_plan(args, folder, compare_cleanrl.saved_total(folder))


@pytest.mark.slow
def test_parity_without_cleanrl_python_is_one_line_of_error(tmp_path):
    (tmp_path / "ppo.py").write_text("")
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks.compare_cleanrl", "--env-id", "CartPole-v1",
         "--cleanrl-dir", str(tmp_path), "--cleanrl-python", str(tmp_path / "no-python"), "--output", str(tmp_path)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert out.returncode == 2
    assert out.stderr == f"error: --cleanrl-python {tmp_path / 'no-python'} is not an executable\n"


def test_same_training_cpu_tells_bit_identical_weights_from_a_difference_of_one_ulp(tmp_path):
    from benchmarks import same_training_cpu

    shipped = ROOT / "tests" / "fixtures" / "cartpole_format2" / "checkpoints" / "step_000000512.pt"
    ckpt = checkpoints.read_checkpoint_file(shipped)
    total = len(ckpt["model"])
    assert same_training_cpu.compare_weights(shipped, shipped) == (total, total, 0.0)
    weight = ckpt["model"]["actor.0.weight"]
    weight.view(-1)[0] = torch.nextafter(weight.view(-1)[0], torch.tensor(float("inf")))
    nudged = tmp_path / "nudged.pt"
    torch.save(ckpt, nudged)
    equal, all_tensors, largest = same_training_cpu.compare_weights(shipped, nudged)
    assert (equal, all_tensors) == (total - 1, total) and 0 < largest < 1e-6
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(same_training_cpu.InputError, match="junk.pt: unreadable checkpoint"):
        same_training_cpu.compare_weights(shipped, tmp_path / "junk.pt")


def test_same_episodes_finds_a_return_one_ulp_off_a_missing_episode_and_skips_unrecorded_columns(tmp_path):
    import math

    from benchmarks import same_episodes

    columns = ["run", "step", "eval_guidance", "policy", "null_branch", "episode_seed", "return", "length", "torch"]
    table = [dict(zip(columns, ["Hopper-v4__ppo__s1", "200000", "1.0", "sample", "learned", str(10000 + k),
                                repr(100.0 + k / 3), "1000", ""], strict=True)) for k in range(3)]  # fmt: skip
    sweep = [dict(row, torch="2.13.0+cpu") for row in table]
    for name, rows in (("table.csv", table), ("sweep.csv", sweep)):
        with open(tmp_path / name, "w", newline="") as f:
            writer = csv.DictWriter(f, columns)
            writer.writeheader()
            writer.writerows(rows)
    assert same_episodes.compare(table, sweep) == ([], {"torch"}, 3)

    off = [dict(row) for row in sweep]
    off[1]["return"] = repr(math.nextafter(float(off[1]["return"]), math.inf))
    off[2]["eval_guidance"] = "1.5"
    problems, _, identical = same_episodes.compare(table, off)
    assert identical == 1 and len(problems) == 2
    assert problems[0].startswith("Hopper-v4__ppo__s1 step 200000 γ 1.0 episode seed 10001: return ")
    assert problems[1].startswith("not in the table")

    script = str(ROOT / "benchmarks" / "same_episodes.py")
    same = subprocess.run([sys.executable, script, str(tmp_path / "table.csv"), str(tmp_path / "sweep.csv")],
                          capture_output=True, text=True)  # fmt: skip
    assert same.returncode == 0, same.stderr
    assert "3 of 3 episodes identical to the table's in every field; empty on one side, not compared: torch\n" in (
        same.stdout
    )
    (tmp_path / "foreign.csv").write_text("a,b\n1,2\n")
    bad = subprocess.run([sys.executable, script, str(tmp_path / "table.csv"), str(tmp_path / "foreign.csv")],
                         capture_output=True, text=True)  # fmt: skip
    assert bad.returncode == 2 and bad.stderr.startswith("error: ") and bad.stderr.count("\n") == 1


def beyond_rows(env, variant, returns_by_step, gammas=(1.0, 1.5)):
    """Episode rows of 5 seeds × 2 episodes: `returns_by_step[step]` is each seed's return at γ = 1 (γ 1.5 the half)."""
    rows = []
    for step, per_seed in returns_by_step.items():
        for gamma in gammas:
            for seed, value in enumerate(per_seed, start=1):
                for episode in range(2):
                    rows.append({"env_id": env, "variant": variant, "config": f"{variant} mujoco=2.3.7", "seed": seed,
                                 "train_guidance": 1.1 if variant != "ppo" else 1.0, "cond_dropout": 0.0,
                                 "step": step, "eval_guidance": gamma, "policy": "sample", "null_branch": "learned",
                                 "return": value / gamma ** 2 + episode})  # fmt: skip
    return rows


def write_rows(path, rows):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_beyond_report_tests_each_new_variant_against_the_tables_baselines(tmp_path):
    from beyond import report as beyond_report

    baseline = {200_000: [1000, 1100, 1200, 1300, 1400], 1_000_000: [2000, 2100, 2200, 2300, 2400]}
    collapsing = {200_000: [1000, 1100, 1200, 1300, 3000], 1_000_000: [2000, 2100, 2200, 2300, 1000]}
    write_rows(tmp_path / "table.csv", beyond_rows("Hopper-v4", "ppo", baseline))
    # a schedule's policy that moved to γ 1.5: its γ = 1 return falls by 3/4, its γ 1.5 one stays above half the best
    moved = [{**r, "return": r["return"] * (5 if r["step"] == 1_000_000 and r["eval_guidance"] == 1.5 else 1)}
             for r in beyond_rows("Hopper-v4", "pgg_adaptive1.1_kl0.04", {200_000: [2000] * 5, 1_000_000: [500] * 5})]  # fmt: skip
    write_rows(tmp_path / "beyond" / "Hopper-v4" / "episodes.csv",
               beyond_rows("Hopper-v4", "pgg_g1to1.2", collapsing) + moved)  # fmt: skip
    write_rows(tmp_path / "beyond" / "Reacher-v4" / "episodes.csv",
               beyond_rows("Reacher-v4", "pgg_g1.1_goal", {1_000_000: [-5, -6, -7, -8, -9]}))  # fmt: skip
    distances = {1.0: 0.10, 1.2: 0.08, 1.5: 0.12}  # goal guidance that brings the fingertip closest at γ = 1.2
    write_rows(tmp_path / "beyond" / "goal_distance.csv",
               [{"env_id": "Reacher-v4", "variant": "pgg_g1.1_goal", "seed": seed, "step": 1_000_000,
                 "eval_guidance": gamma, "final_distance": d + 0.01 * seed}
                for gamma, d in distances.items() for seed in (1, 2)])  # fmt: skip
    # γ_train logged at each iteration's step; the checkpoints of 200k and 1M are saved after the iterations of 200704
    # and 1001472, the first to reach their marks
    trajectory = {198_656: 1.0, 200_704: 1.05, 999_424: 1.1, 1_001_472: 1.2}
    write_rows(tmp_path / "beyond" / "guidance_trajectory.csv",
               [{"env_id": "Hopper-v4", "variant": "pgg_g1to1.2", "seed": 1, "step": step, "guidance": g, "kl": 0.01}
                for step, g in trajectory.items()])  # fmt: skip
    args = beyond_report.Args(folder=str(tmp_path / "beyond"), table=str(tmp_path / "table.csv"),
                              table_heldout=str(tmp_path / "none.csv"))  # fmt: skip
    written = beyond_report.report(args)
    text = (tmp_path / "beyond" / "report.md").read_text()
    assert "| PGG, γ_train 1 → 1.2 | 1.050 (1.050–1.050) | 1.200 (1.200–1.200) |" in text
    with open(tmp_path / "beyond" / "report_values.csv", newline="") as f:
        values = {
            (r["env_id"], r["variant"], r["baseline"], r["quantity"]): float(r["value"]) for r in csv.DictReader(f)
        }
    assert values[("Reacher-v4", "pgg_g1.1_goal", "", "distance largest vs γ 1 (%)")] == pytest.approx(
        100 * 0.02 / 0.115
    )
    assert values[("Hopper-v4", "pgg_g1to1.2", "", "γ_train mean at 1M")] == 1.2
    text = (tmp_path / "beyond" / "report.md").read_text()
    assert "| Reacher-v4 | PGG, γ_train = 1.1, goal null | 0.1150 | 1.2: 0.0950 | 1.5: 0.1350 | +17.4% |" in text
    assert "| PGG, γ_train 1 → 1.2 | 1M |" not in text  # rows are variant | baseline | step
    assert "| PGG, γ_train 1 → 1.2 | PPO | 1M | -280.0 |" in text  # (2000+…+1000)/5 − (2000+…+2400)/5
    assert "| n/a | n/a |" in text.split("## Reacher-v4")[1]  # half a cost means nothing
    task = text.split("## Hopper-v4")[1].split("## Reacher-v4")[0]
    fell = task.split("fell at its best γ |")[1].split("\n\n")[0]
    assert "| 5 | 5 |" in fell  # seed 5 fell below half its best mark at γ = 1 and at its best γ
    assert "| 1, 2, 3, 4, 5 | none |" in fell  # the moved policy fell at γ = 1 only
    with open(written[1], newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["variant"] == "pgg_g1to1.2"]
    assert [r["step"] for r in rows] == ["200000", "1000000"] and float(rows[1]["p_holm"]) >= float(rows[1]["p"])
    # γ 1.5 returns are about the γ 1 ones / 2.25: the fall from the best γ to 1.5 is −55.5%
    assert "-55.5%" in task.split("vs best |")[1]
    # the glance table (means over two episodes, +0.5): γ = 1 is best at 1M, and seed 5 collapsed
    glance = text.split("## At a glance")[1].split("## Hopper-v4")[0]
    assert "| Hopper-v4 | PGG, γ_train 1 → 1.2 | 1920.5 | 1: 1920.5 | 1.5: 853.8 | -55.5% | 1 of 5 | 1 of 5 |" in glance
    assert "| Hopper-v4 | PPO | 2200.5 | 1: 2200.5 | 1.5: 978.3 | -55.5% | 0 of 5 | 0 of 5 |" in glance
    # (500 / 2.25 + 0.5) × 5 = 1113.6 at γ 1.5 against 2000.5 at γ 1 at 200k: fell at γ = 1 only
    assert "| 500.5 | 1.5: 1113.6 | 1.5: 1113.6 | +0.0% | 5 of 5 | 0 of 5 |" in glance
    # its seeds do not fall from their best γ (1.5) to the largest (1.5); PPO's fall from γ 1 by 55.5% each
    fall = glance.split("| Hopper-v4 | PGG, adaptive γ_train from 1.1, KL target 0.04 | PPO | ")[1].split("\n")[0]
    assert fall.startswith("1.5 (1) | +0.0% | -55.5% | +55.5 pts | <0.001 (<0.001) |")


def test_beyond_report_tests_each_schedules_fall_from_its_best_gamma_against_the_baselines():
    """Seeds of different shapes, a best γ inside the swept range, and two baselines: each fall is the seed's
    own (largest γ − best γ of the mean) / best, Welch's unequal-variance p as scipy gives it, Holm over the two."""
    from scipy import stats

    from beyond import schedules
    from paper_study import stats as study_stats

    returns = {  # per eval γ at 1M, seeds 1–4
        "pgg_g1to1.2": {1.0: [1000, 1100, 900, 1000], 1.2: [2000, 2200, 1900, 2100], 1.5: [1500, 1300, 1700, 1400]},
        "ppo": {1.0: [2000, 2100, 1900, 2050], 1.2: [1500, 1600, 1400, 1500], 1.5: [800, 1000, 700, 900]},
        "pgg_g1.1": {1.0: [1800, 1700, 1900, 1750], 1.2: [2100, 2000, 2300, 2050], 1.5: [1900, 1500, 2200, 1600]},
    }
    means = {("Hopper-v4", v, 1_000_000, g): dict(enumerate(values, start=1))
             for v, by_gamma in returns.items() for g, values in by_gamma.items()}  # fmt: skip
    rows = schedules.fall_tests(means, {"Hopper-v4": ["ppo", "pgg_g1.1", "pgg_g1to1.2"]})
    falls = {v: [(worst - best) / best for best, worst in zip(r[1.2 if v != "ppo" else 1.0], r[1.5])]
             for v, r in returns.items()}  # fmt: skip
    p = [stats.ttest_ind(falls["pgg_g1to1.2"], falls[b], equal_var=False).pvalue for b in ("ppo", "pgg_g1.1")]
    assert [(r["baseline"], r["best"], r["baseline_best"]) for r in rows] == [("ppo", 1.2, 1.0), ("pgg_g1.1", 1.2, 1.2)]
    assert [r["fall"] for r in rows] == pytest.approx([np.mean(falls["pgg_g1to1.2"])] * 2)
    assert [r["baseline_fall"] for r in rows] == pytest.approx([np.mean(falls["ppo"]), np.mean(falls["pgg_g1.1"])])
    assert [r["p"] for r in rows] == pytest.approx(p)
    assert [r["p_holm"] for r in rows] == pytest.approx([min(1, 2 * min(p)) if x == min(p) else max(min(1, 2 * min(p)), x)
                                                         for x in p])  # fmt: skip
    # Holm over the falls and other tests (the report's γ = 1 ones): a family of 2 + 3
    joint = schedules.fall_tests(means, {"Hopper-v4": ["ppo", "pgg_g1.1", "pgg_g1to1.2"]}, [0.5, 0.9, 1e-6])
    assert [r["p_holm_with_gamma_one"] for r in joint] == pytest.approx(study_stats.holm([*p, 0.5, 0.9, 1e-6])[:2])
    assert [r["p_holm"] for r in joint] == [r["p_holm"] for r in rows]  # the falls' own family is unchanged
    # the return at each side's own best γ: 1.2 for the schedule, 1 for PPO, 1.2 for the constant
    at_best = [stats.ttest_ind(returns["pgg_g1to1.2"][1.2], returns[b][g], equal_var=False).pvalue
               for b, g in (("ppo", 1.0), ("pgg_g1.1", 1.2))]  # fmt: skip
    assert [r["return"] - r["baseline_return"] for r in rows] == pytest.approx([37.5, -62.5])
    assert [r["return_p"] for r in rows] == pytest.approx(at_best)
    assert [r["return_p_holm"] for r in rows] == pytest.approx(study_stats.holm(at_best))
    assert schedules.collapsed({(1_000_000, 1.0): {1: -40.0}, (200_000, 1.0): {1: -60.0}}) is None  # costs


def test_beyond_report_pairs_goal_distances_by_seed_and_draws_only_the_variants_its_tables_hold(monkeypatch, tmp_path):
    """Each seed's change in distance from γ = 1 to the largest γ, paired by seed (a seed missing at one γ is left
    out), a one-sample t test of the changes; a variant of goal_distance.csv that no table holds is not drawn."""
    from scipy import stats

    from beyond import figures, goals

    distance = {("Reacher-v4", "ppo", 1.0): {1: 0.1, 2: 0.2, 3: 0.3, 4: 0.2},
                ("Reacher-v4", "ppo", 1.5): {1: 0.15, 2: 0.18, 3: 0.4},
                ("Reacher-v4", "pgg_drop0.1", 1.0): {1: 0.1}, ("Reacher-v4", "pgg_drop0.1", 1.5): {1: 0.3}}  # fmt: skip
    (row,) = goals.distance_tests(distance, {"Reacher-v4": ["ppo"]})
    assert (row["farther"], row["seeds"]) == (2, 3)
    assert row["p"] == pytest.approx(stats.ttest_1samp([0.05, -0.02, 0.1], 0.0).pvalue) and row["p_holm"] == row["p"]
    drawn = []
    monkeypatch.setattr(figures, "band", lambda ax, xs, values, variant: drawn.append(variant))
    figures.distance_figure(distance, {"Reacher-v4": ["ppo"]}, tmp_path / "goal_distance.png")
    assert drawn == ["ppo"]


def test_goal_distance_is_the_fingertip_to_target_distance_of_the_last_observation():
    import ppo_pgg_continuous
    from beyond import goal_distance
    from pgg_utils import evaluation

    torch.manual_seed(0)
    agent = ppo_pgg_continuous.Agent(11, 2, null_dims=(4, 5, 8, 9, 10), action_bounds=(-np.ones(2), np.ones(2)))
    ckpt = {"env_id": "Reacher-v4", "action_space": "continuous", "obs_dim": 11, "action_dim": 2}
    policy = evaluation.GuidedPolicy(agent, ckpt)
    (total, distance), *_ = goal_distance.final_distances(policy, ckpt, 1.5, 2, 10_000)
    env = policy.make_env()  # the same episode by hand: its fingertip-to-target vector at the end
    obs, _ = env.reset(seed=10_000)
    noise = evaluation.episode_noise("continuous", 10_000, 0, 50, 2)
    for t in range(50):
        obs, *_ = env.step(policy.act(obs[None], np.array([1.5]), noise[t : t + 1], False)[0])
    assert distance == pytest.approx(np.linalg.norm(obs[8:11])) and total < 0


@pytest.mark.slow
def test_the_committed_beyond_report_is_what_its_committed_csvs_give(tmp_path):
    """results/beyond/report.md, report.csv and report_values.csv regenerate from the committed CSVs alone: a changed script or CSV
    whose report was not rewritten fails here. Floats are compared to 1e-9 (another CPU may round a sum
    differently); the report's rounded text exactly, but for its line naming the folder."""
    from beyond import report as beyond_report
    from beyond import sets as beyond_sets

    beyond = ROOT / "results" / "beyond"
    for path in [*beyond.glob("*/episodes.csv"), *beyond.glob("*/heldout_gamma.csv"), *beyond.glob("*.csv"),
                 *beyond.glob(f"{beyond_sets.BC_FOLDER}/*.csv"),
                 *beyond.glob(f"{beyond_sets.BC_TRAIN_FOLDER}/*/episodes.csv"),
                 *beyond.glob(f"{beyond_sets.BC_TRAIN_FOLDER}/*/heldout_gamma.csv"),
                 *beyond.glob(f"{beyond_sets.BC_TRAIN_FOLDER}/*/heldout_fresh.csv"),
                 *beyond.glob(f"{beyond_sets.COMMAND_FOLDER}/*.csv"), *beyond.glob("*/learned_null.csv"),
                 *beyond.glob(f"{beyond_sets.DROPOUT_FOLDER}/*.csv"),
                 *beyond.glob(f"{beyond_sets.DROPOUT_FOLDER}/*/tracking.csv"),
                 *beyond.glob(f"{beyond_sets.DROPOUT_FOLDER}/*/learned_null.csv")]:  # fmt: skip
        (tmp_path / path.relative_to(beyond)).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path.relative_to(beyond)).write_bytes(path.read_bytes())
    continuous = ROOT / "results" / "continuous"
    beyond_report.report(beyond_report.Args(folder=str(tmp_path), table=str(continuous / "episodes.csv"),
                                            table_heldout=str(continuous / "heldout_gamma.csv")))  # fmt: skip
    ours, committed = ((folder / "report.md").read_text().splitlines() for folder in (tmp_path, beyond))
    assert [line for line in ours if not line.startswith("Generated by")] == [
        line for line in committed if not line.startswith("Generated by")
    ]
    for name in ("report.csv", "report_values.csv"):
        with open(tmp_path / name, newline="") as f, open(beyond / name, newline="") as g:
            for mine, theirs in zip(csv.DictReader(f), csv.DictReader(g), strict=True):
                assert mine.keys() == theirs.keys()
                for key in mine:
                    try:
                        assert float(mine[key]) == pytest.approx(float(theirs[key]), rel=1e-9, nan_ok=True)
                    except ValueError:
                        assert mine[key] == theirs[key]


def test_beyond_report_question_3_pairs_each_agents_own_null_with_its_behaviour_cloned_one(tmp_path):
    """The same agents with another null: each side's best γ chosen on the sweep and scored on the fresh
    episodes, each seed's fall and return there, the cloned null's minus the own null's, paired by seed
    (checked against scipy's paired t test, on seeds matched by number, not by position); the detectable
    difference is where the paired test's power reaches 80%; n/a where no seed differs."""
    from scipy import stats

    from beyond import fitted_null
    from beyond import report as beyond_report
    from beyond import sets as beyond_sets
    from paper_study import stats as study_stats

    def cloned(rows, episode_seed):
        gain = {1.0: 0.0, 1.2: 0.1, 1.5: 0.05}  # the cloned null gains at 1.2 and keeps most of it at 1.5
        return [{**r, "config": "ppo null=bc mujoco=2.3.7", "null_branch": "bc", "episode_seed": episode_seed,
                 "return": r["return"] * (1.0 if r["eval_guidance"] == 1.0 else 1.5**2 / r["eval_guidance"] ** 2)
                 + 40 * gain[r["eval_guidance"]] * r["seed"] ** 2} for r in rows]  # fmt: skip

    own = beyond_rows("Hopper-v4", "ppo", {1_000_000: [2000, 2100, 2200, 2300, 2400]}, gammas=(1.0, 1.2, 1.5))
    own_fresh = beyond_rows("Hopper-v4", "ppo", {1_000_000: [2050, 2000, 2250, 2200, 2500]}, gammas=(1.0, 1.2, 1.5))
    folder = tmp_path / "beyond" / beyond_sets.BC_FOLDER
    write_rows(tmp_path / "table.csv", own)
    write_rows(folder / "episodes.csv", cloned(own, 10_000))
    write_rows(folder / "heldout_fresh.csv", cloned(own_fresh[::-1], 20_000))  # rows in another order
    write_rows(folder / "own_null_fresh.csv", own_fresh)
    none = str(tmp_path / "none.csv")
    args = beyond_report.Args(folder=str(tmp_path / "beyond"), table=str(tmp_path / "table.csv"), table_heldout=none,
                              discrete_table=none, discrete_heldout=none)  # fmt: skip
    means, fresh, sets, heldout = fitted_null.read_bc(tmp_path / "beyond", args)
    assert sets == [("Hopper-v4", "ppo")] and not heldout
    values = []
    lines = fitted_null.bc_section(means, fresh, sets, heldout, values)
    number = {(r["variant"], r["baseline"], r["quantity"]): r["value"] for r in values}
    bc = "ppo" + beyond_sets.BC
    best_own, best_bc = number[("ppo", "question 3", "best γ")], number[(bc, "question 3", "best γ")]
    at = lambda key, gamma: fresh[("Hopper-v4", key, 1_000_000, gamma)]
    returns_bc, returns_own = at(bc, best_bc), at("ppo", best_own)
    seeds = sorted(returns_own)
    assert number[(bc, "ppo", "return p")] == pytest.approx(
        stats.ttest_rel([returns_bc[s] for s in seeds], [returns_own[s] for s in seeds]).pvalue
    )
    falls = lambda key, best: [(at(key, 1.5)[s] - at(key, best)[s]) / abs(at(key, best)[s]) for s in seeds]
    fall_difference = np.subtract(falls(bc, best_bc), falls("ppo", best_own))
    assert number[(bc, "ppo", "fall difference (pts)")] == pytest.approx(100 * fall_difference.mean())
    assert number[(bc, "ppo", "fall p")] == pytest.approx(stats.ttest_1samp(fall_difference, 0.0).pvalue)
    assert number[(bc, "ppo", "fall p Holm")] == pytest.approx(number[(bc, "ppo", "fall p")])  # a family of one
    sd = np.std(np.subtract([returns_bc[s] for s in seeds], [returns_own[s] for s in seeds]), ddof=1)
    power = stats.nct.sf(stats.t.ppf(0.975, 4), 4, number[(bc, "ppo", "return detectable")] * np.sqrt(5) / sd)
    assert power == pytest.approx(0.8, abs=1e-6)
    assert number[("", "question 3", "γ = 1 cells equal")] == 1
    assert any("| Hopper-v4 | PPO | behaviour-cloned |" in line for line in lines)
    assert study_stats.paired_test({1: 1.0, 2: 2.0}, {1: 0.0, 2: 0.5}) is None  # two seeds: no test
    assert study_stats.paired_test({1: 1.0, 2: 1.0, 3: 1.0}, {1: 1.0, 2: 1.0, 3: 1.0}) is None  # no spread
