import csv
import math
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from conftest import ROOT


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two tiny discrete runs (seeds 1, 2) and one tiny continuous run, each with two checkpoints."""
    root = tmp_path_factory.mktemp("runs")
    for seed in (1, 2):
        args = ppo_pgg_discrete.Args(
            total_timesteps=4096, checkpoint_interval=2048, seed=seed, guidance=1.1, output_dir=str(root / "discrete"),
        )  # fmt: skip
        ppo_pgg_discrete.train(args, ppo_pgg_discrete.prepare_run_dir(args))
    args = ppo_pgg_continuous.Args(
        env_id="Hopper-v4", total_timesteps=2048, num_steps=1024, num_minibatches=8, update_epochs=2,
        checkpoint_interval=1024, guidance=1.1, output_dir=str(root / "continuous"),
    )  # fmt: skip
    ppo_pgg_continuous.train(args, ppo_pgg_continuous.prepare_run_dir(args))
    return root


def checkpoint(root: Path, kind: str) -> Path:
    return sorted((root / kind).rglob("step_*.pt"))[-1]


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("deterministic", [False, True])
def test_batched_evaluator_equals_sequential_reference(runs, kind, deterministic):
    agent, ckpt = sweep.load_any_checkpoint(checkpoint(runs, kind))
    policy = sweep.GuidedPolicy(agent, ckpt)
    gammas = (1.0, 1.5, 3.0)
    returns, lengths, steps = sweep.evaluate_batched(policy, ckpt, gammas, 6, 10_000, deterministic)
    assert steps == lengths.sum() and len(set(lengths.ravel().tolist())) > 1  # episodes end at different times
    for g, gamma in enumerate(gammas):
        ref_returns, ref_lengths = sweep.evaluate_sequential(policy, ckpt, gamma, 6, 10_000, deterministic)
        np.testing.assert_array_equal(returns[g], ref_returns)
        np.testing.assert_array_equal(lengths[g], ref_lengths)


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_eval_at_training_guidance_reproduces_training_policy(runs, kind):
    agent, ckpt = sweep.load_any_checkpoint(checkpoint(runs, kind))
    policy = sweep.GuidedPolicy(agent, ckpt)
    raw = np.random.default_rng(0).normal(size=(16, ckpt["obs_dim"])) * 0.5
    guidance = ckpt["args"]["guidance"]
    evaluated = policy.guided(raw, np.full(16, guidance))
    with torch.no_grad():  # the policy that acted in training rollouts, and the one PPO optimised
        if kind == "discrete":
            obs = torch.as_tensor(raw, dtype=torch.float32)
            acted = ppo_pgg_discrete.guide(agent.actor(obs), agent.unconditional_logits(), guidance)
            optimised = agent.guided_logits(obs, guidance)
        else:
            obs = agent.obs_norm(raw)
            acted = ppo_pgg_continuous.guide(agent.actor_mean(obs), agent.unconditional_mean(), guidance)
            optimised = agent.guided_mean(obs, guidance)
    assert torch.equal(evaluated, acted)
    torch.testing.assert_close(evaluated, optimised, rtol=1e-6, atol=1e-6)


def test_continuous_actions_are_clipped_to_the_env_bounds(runs):
    agent, ckpt = sweep.load_any_checkpoint(checkpoint(runs, "continuous"))
    assert ckpt["action_low"] == [-1.0] * 3 and ckpt["action_high"] == [1.0] * 3  # Hopper's, not ClipAction's
    # Checkpoints saved before the fix hold ClipAction's infinite bounds; the env's still apply.
    ckpt = {**ckpt, "action_low": [-math.inf] * 3, "action_high": [math.inf] * 3}
    policy = sweep.GuidedPolicy(agent, ckpt)
    raw = np.random.default_rng(2).normal(size=(64, ckpt["obs_dim"]))
    noise = np.random.default_rng(3).normal(size=(64, 3)) * 5
    actions = policy.act(raw, np.full(64, 30.0), noise, deterministic=False)
    assert np.abs(actions).max() == 1.0 and (np.abs(actions) == 1.0).mean() > 0.5


def test_a_fix_that_changes_results_invalidates_earlier_cells(runs, tmp_path, monkeypatch):
    settings = (50, 10_000, False, False)
    before = sweep.cell_path(tmp_path, checkpoint(runs, "continuous"), 1.0, settings)
    assert sweep.cell_path(tmp_path, checkpoint(runs, "continuous"), 1.0, settings) == before
    monkeypatch.setattr(sweep, "EVALUATOR_REVISION", sweep.EVALUATOR_REVISION + 1)
    assert sweep.cell_path(tmp_path, checkpoint(runs, "continuous"), 1.0, settings) != before


def test_cells_follow_a_checkpoint_copied_elsewhere_but_not_a_changed_one(runs, tmp_path):
    settings = (50, 10_000, False, False)
    original = checkpoint(runs, "continuous")
    moved = tmp_path / "elsewhere" / original.relative_to(runs)
    moved.parent.mkdir(parents=True)
    shutil.copy(original, moved)  # a new path and a new timestamp, as on another machine
    assert moved.stat().st_mtime_ns != original.stat().st_mtime_ns
    output = tmp_path / "sweep"
    assert sweep.cell_path(output, moved, 1.0, settings) == sweep.cell_path(output, original, 1.0, settings)
    changed = tmp_path / "changed" / original.relative_to(runs)
    changed.parent.mkdir(parents=True)
    changed.write_bytes(original.read_bytes() + b"\0")
    assert sweep.cell_path(output, changed, 1.0, settings) != sweep.cell_path(output, original, 1.0, settings)


def test_uniform_null_control_is_temperature_scaling(runs):
    agent, ckpt = sweep.load_any_checkpoint(checkpoint(runs, "discrete"))
    raw = np.random.default_rng(1).normal(size=(10, 4)) * 0.1
    learned = sweep.GuidedPolicy(agent, ckpt).guided(raw, np.full(10, 3.0)).softmax(-1)
    uniform = sweep.GuidedPolicy(agent, ckpt, uniform_null=True).guided(raw, np.full(10, 3.0)).softmax(-1)
    with torch.no_grad():
        tempered = (3.0 * agent.actor(torch.as_tensor(raw, dtype=torch.float32))).softmax(-1)
    torch.testing.assert_close(uniform, tempered)
    assert not torch.allclose(learned, tempered)


def test_ci_against_hand_computed_values():
    # mean 3; s = sqrt(2.5) = 1.58114; t_{0.975,4} = 2.776445; half = 2.776445 * 1.58114 / sqrt(5) = 1.963243
    mean, half, low, high = sweep.mean_ci95([1, 2, 3, 4, 5])
    assert mean == 3 and half == pytest.approx(1.963243, abs=1e-6) and low == pytest.approx(3 - 1.963243, abs=1e-6)
    assert sweep.mean_ci95([500, 500, 500])[1] == 0.0
    assert math.isnan(sweep.mean_ci95([7.0])[1])
    mean, half, low, high = sweep.mean_ci95([1, 2, 3, 4, 5], method="bootstrap")
    assert mean == 3 and 1.8 <= low <= 2.2 and 3.8 <= high <= 4.2 and half == pytest.approx((high - low) / 2)


def test_summary_aggregates_per_seed_means():
    rows = [
        {"env_id": "E", "variant": "v", "train_guidance": 1.1, "cond_dropout": 0.0, "step": 100, "eval_guidance": 2.0,
         "policy": "sample", "null_branch": "learned", "seed": seed, "return": r}
        for seed, returns in [(1, [10, 20]), (2, [40, 40]), (3, [0, 60])]
        for r in returns
    ]  # fmt: skip
    (row,) = sweep.summarise(rows)
    assert row["n_seeds"] == 3 and row["n_episodes"] == 6 and row["mean"] == round(85 / 3, 4)
    assert row["seed_means"] == "15.0000;40.0000;30.0000"
    assert row["ci95"] == pytest.approx(round(sweep.mean_ci95([15, 40, 30])[1], 4))


def sweep_args(runs, output, **overrides):
    return replace(sweep.Args(paths=(str(runs / "discrete"),), output=str(output), gammas=(1.0, 2.0), episodes=4), **overrides)


def test_resume_after_interruption_gives_same_csv(runs, tmp_path, monkeypatch):
    sweep.sweep(sweep_args(runs, tmp_path / "whole"))
    expected = (tmp_path / "whole" / "episodes.csv").read_text()

    calls = {"n": 0}
    real_run_job = sweep.run_job

    def crash_after_two(job):
        calls["n"] += 1
        if calls["n"] > 2:
            raise KeyboardInterrupt
        return real_run_job(job)

    monkeypatch.setattr(sweep, "run_job", crash_after_two)
    with pytest.raises(KeyboardInterrupt):
        sweep.sweep(sweep_args(runs, tmp_path / "resumed"))
    assert len(list((tmp_path / "resumed" / "cells").glob("*.csv"))) == 4  # two checkpoints × two γ
    assert not (tmp_path / "resumed" / "episodes.csv").exists()

    evaluated = []
    monkeypatch.setattr(sweep, "run_job", lambda job: evaluated.append(job) or real_run_job(job))
    sweep.sweep(sweep_args(runs, tmp_path / "resumed"))
    assert len(evaluated) == 2  # only the checkpoints not finished before the crash
    text = (tmp_path / "resumed" / "episodes.csv").read_text()
    assert text == expected
    rows = list(csv.DictReader(text.splitlines()))
    assert len(rows) == 4 * 2 * 4  # checkpoints × γ × episodes, no duplicates
    assert len({(r["run"], r["step"], r["eval_guidance"], r["episode"]) for r in rows}) == len(rows)
    summary = list(csv.DictReader((tmp_path / "resumed" / "summary.csv").read_text().splitlines()))
    assert {r["n_seeds"] for r in summary} == {"2"}


def test_corrupt_checkpoint_is_skipped_and_reported(runs, tmp_path):
    bad_run = tmp_path / "bad" / "checkpoints"
    bad_run.mkdir(parents=True)
    (bad_run / "step_000000100.pt").write_bytes(b"not a checkpoint")
    out = sweep.sweep(sweep_args(runs, tmp_path / "out", paths=(str(runs / "discrete"), str(tmp_path / "bad"))))
    skipped = list(csv.DictReader((out / "skipped.csv").read_text().splitlines()))
    assert len(skipped) == 1 and "step_000000100.pt" in skipped[0]["reason"]
    assert len(list(csv.DictReader((out / "episodes.csv").read_text().splitlines()))) == 4 * 2 * 4


@pytest.mark.parametrize(
    "argv,message",
    [
        (["/no/such/dir"], "no such file or directory"),
        (["{empty}"], "no checkpoints"),
        (["{runs}", "--gammas", "1", "nan"], "--gammas must be finite"),
        (["{runs}", "--steps", "12345"], "no checkpoint at steps"),
        (["{corrupt}"], "no checkpoint could be evaluated"),
    ],
)
def test_bad_input_exits_with_one_line(runs, tmp_path, argv, message):
    (tmp_path / "empty").mkdir()
    (tmp_path / "corrupt" / "checkpoints").mkdir(parents=True)
    (tmp_path / "corrupt" / "checkpoints" / "step_000000001.pt").write_bytes(b"\x00" * 10)
    argv = [a.format(empty=tmp_path / "empty", runs=runs / "discrete", corrupt=tmp_path / "corrupt") for a in argv]
    proc = subprocess.run(
        [sys.executable, str(ROOT / "eval_gamma_sweep.py"), *argv, "--output", str(tmp_path / "o")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2 and len(errors) == 1 and message in errors[0] and "Traceback" not in proc.stderr
