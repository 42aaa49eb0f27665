import csv
import dataclasses
import hashlib
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import ROOT, default_sigint, train

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import cells, episodes, evaluation, files, identity
from pgg_utils import sweep as engine
from pgg_utils.checkpoints import checkpoint_step
from pgg_utils.files import read_csv
from pgg_utils.processes import start_pool, stop_pool

SCRIPT = [sys.executable, str(ROOT / "eval_gamma_sweep.py")]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two tiny discrete runs (seeds 1, 2), a third (seed 1 at another learning rate) in discrete_lr/,
    and one tiny continuous run, each with two checkpoints."""
    root = tmp_path_factory.mktemp("runs")
    for seed in (1, 2):
        args = ppo_pgg_discrete.Args(
            total_timesteps=4096, checkpoint_interval=2048, seed=seed, guidance=1.1, output_dir=str(root / "discrete"),
        )  # fmt: skip
        train(ppo_pgg_discrete, args)
    args = ppo_pgg_discrete.Args(  # seed 1 again, another learning rate: another experiment
        total_timesteps=4096, checkpoint_interval=2048, seed=1, guidance=1.1, learning_rate=0.002,
        output_dir=str(root / "discrete_lr"),
    )  # fmt: skip
    train(ppo_pgg_discrete, args)
    args = ppo_pgg_continuous.Args(
        env_id="Hopper-v4", total_timesteps=2048, num_steps=1024, num_minibatches=8, update_epochs=2,
        checkpoint_interval=1024, guidance=1.1, output_dir=str(root / "continuous"),
    )  # fmt: skip
    train(ppo_pgg_continuous, args)
    return root


def checkpoint(root: Path, kind: str) -> Path:
    return max((root / kind).rglob("step_*.pt"))


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("deterministic", [False, True])
def test_batched_evaluator_agrees_with_sequential_reference(runs, kind, deterministic):
    """The batched cells against the reference: one env, one episode at a time, one observation per
    forward (padded to 8 rows). With 10 episodes a cell's products have 10 rows and the reference's 8,
    which a BLAS may round differently (MKL with AVX-512 on Intel CPUs does, by ~1e-7 relative; the
    AMD EPYC this was written on does not). So returns are compared to rtol 1e-4. Discrete lengths,
    and CartPole's returns (one point a step), must match exactly: they change only where rounding
    flips a sampled or greedy action, which needs two noise-perturbed logits within ~1e-6 of each
    other. Continuous lengths are not asserted separately: a Hopper episode one step longer or
    shorter would change its return by a step's reward (~1), far beyond rtol."""
    agent, ckpt = evaluation.load_any_checkpoint(checkpoint(runs, kind))
    policy = evaluation.GuidedPolicy(agent, ckpt)
    gammas = (1.0, 1.5, 3.0)
    for gamma in gammas:
        cell = evaluation.evaluate_cell(policy, ckpt, gamma, 10, 10_000, deterministic)  # the sweep's cell
        returns, lengths = cell["return"], cell["length"]
        assert len(set(lengths.tolist())) > 1  # its episodes end at different times
        # The reference: episode k alone, a cell of one episode whose episode 0 is the cell's k (same seed, noise).
        alone = [evaluation.evaluate_cell(policy, ckpt, gamma, 1, 10_000 + k, deterministic) for k in range(10)]
        ref_returns = np.concatenate([one["return"] for one in alone])
        ref_lengths = np.concatenate([one["length"] for one in alone])
        np.testing.assert_allclose(returns, ref_returns, rtol=1e-4)
        if kind == "discrete":
            np.testing.assert_array_equal(lengths, ref_lengths)
            np.testing.assert_array_equal(returns, ref_returns)


def record_forward_rows(monkeypatch, perturb: float = 0.0) -> list[int]:
    """Records the row count of every Linear product from now on. With `perturb`, also emulates a
    BLAS whose rounding depends on the row count (as MKL's does on Intel CPUs), exaggerated so that
    it shows in the returns: each product is scaled by 1 + perturb * (rows % 5)."""
    rows, real_linear = [], torch.nn.functional.linear

    def linear(x, weight, bias=None):
        rows.append(x.shape[0] if x.dim() > 1 else 1)
        out = real_linear(x, weight, bias)
        return out * (1 + perturb * (rows[-1] % 5)) if perturb else out

    monkeypatch.setattr(torch.nn.functional, "linear", linear)
    return rows


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_every_forward_of_a_cell_has_the_same_shape(runs, kind, monkeypatch):
    agent, ckpt = evaluation.load_any_checkpoint(checkpoint(runs, kind))
    policy = evaluation.GuidedPolicy(agent, ckpt)
    rows = record_forward_rows(monkeypatch)
    lengths = np.stack(
        [evaluation.evaluate_cell(policy, ckpt, gamma, 10, 10_000, False)["length"] for gamma in (1.0, 2.0)]
    )
    assert len(set(lengths.ravel().tolist())) > 1  # episodes ended at different times, yet:
    assert set(rows) == {evaluation.cell_rows(10)}
    assert len(rows) == 3 * (lengths[0].max() + lengths[1].max())  # three Linear layers a step, per cell


def cell_texts(output: Path, gamma: float) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted((output / "cells").glob(f"*__g{gamma:g}__*.csv"))}


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_a_cell_does_not_depend_on_what_else_is_swept(runs, kind, tmp_path, monkeypatch):
    """The same cell, swept alone, beside other γ values (two worker processes), and in a sweep that
    was interrupted and resumed, is the same file to the bit; under an emulated BLAS whose rounding
    depends on the row count too, which is what broke it on Intel CPUs."""
    record_forward_rows(monkeypatch, perturb=0.1)
    paths = (str(runs / kind),)
    alone = sweep_args(runs, tmp_path / "alone", paths=paths, gammas=(2.0,))
    sweep.sweep(alone)
    expected = cell_texts(tmp_path / "alone", 2.0)
    assert len(expected) == (2 if kind == "continuous" else 4)
    sweep.sweep(replace(alone, output=str(tmp_path / "beside"), gammas=(1.0, 2.0, 3.0, 5.0), workers=2))
    assert cell_texts(tmp_path / "beside", 2.0) == expected

    real_run_job, calls = engine.run_job, []

    def interrupt_third(job):
        calls.append(job)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real_run_job(job)

    monkeypatch.setattr(engine, "run_job", interrupt_third)
    resumed = replace(alone, output=str(tmp_path / "resumed"), gammas=(3.0, 2.0, 1.0))
    with pytest.raises(KeyboardInterrupt):
        sweep.sweep(resumed)
    monkeypatch.setattr(engine, "run_job", real_run_job)
    sweep.sweep(resumed)
    assert cell_texts(tmp_path / "resumed", 2.0) == expected
    episodes = (tmp_path / "resumed" / "episodes.csv").read_text()
    cell_lines = [line.rsplit(",", 1)[0] for text in expected.values() for line in text.splitlines()[1:]]
    assert all(line in episodes for line in cell_lines)  # each cell row, its checksum left out


def guided_branch(agent, ckpt, raw, guidance, uniform_null=False):
    """The guided logits or means the sweep's GuidedPolicy acts on."""
    null = evaluation.GuidedPolicy(agent, ckpt, uniform_null).null
    if ckpt["action_space"] == "continuous":
        return agent.acting_policy(raw, guidance, **null).mean
    return agent.acting_policy(raw.astype(np.float32), guidance, **null).logits


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_eval_at_training_guidance_reproduces_training_policy(runs, kind):
    agent, ckpt = evaluation.load_any_checkpoint(checkpoint(runs, kind))
    raw = np.random.default_rng(0).normal(size=(16, ckpt["obs_dim"])) * 0.5
    guidance = ckpt["args"]["guidance"]
    evaluated = torch.from_numpy(guided_branch(agent, ckpt, raw, guidance))
    # The mixture that acted in training rollouts (numpy, on the actor's output), and the policy PPO
    # optimised (torch.lerp, equal to the last bit or so).
    with torch.no_grad():
        if kind == "discrete":
            obs = torch.as_tensor(raw, dtype=torch.float32)
            acted = ppo_pgg_discrete.guide(agent.actor(obs).numpy(), agent.unconditional_logits().numpy(), guidance)
            optimised = agent.policy(obs, guidance).logits
        else:
            obs = agent.obs_norm(raw)
            acted = ppo_pgg_continuous.guide(
                agent.actor_mean(obs).numpy(), agent.unconditional_mean().numpy(), guidance
            )
            optimised = agent.policy(obs, guidance).mean
    np.testing.assert_array_equal(evaluated.numpy(), acted)
    torch.testing.assert_close(evaluated, optimised, rtol=1e-6, atol=1e-6)


def test_continuous_actions_are_clipped_to_the_env_bounds(runs):
    agent, ckpt = evaluation.load_any_checkpoint(checkpoint(runs, "continuous"))
    assert ckpt["action_low"] == [-1.0] * 3 and ckpt["action_high"] == [1.0] * 3  # Hopper's, not ClipAction's
    # Checkpoints saved before the fix hold ClipAction's infinite bounds; the env's still apply.
    ckpt = {**ckpt, "action_low": [-math.inf] * 3, "action_high": [math.inf] * 3}
    policy = evaluation.GuidedPolicy(agent, ckpt)
    raw = np.random.default_rng(2).normal(size=(64, ckpt["obs_dim"]))
    noise = np.random.default_rng(3).normal(size=(64, 3)) * 5
    actions = policy.act(raw, np.full(64, 30.0), noise, deterministic=False)
    assert np.abs(actions).max() == 1.0 and (np.abs(actions) == 1.0).mean() > 0.5


def cell_file(output, checkpoint_file, gamma, settings, digest=None) -> Path:
    """cells.cell_path of a checkpoint file as a sweep in this process names it."""
    digest = digest or hashlib.sha1(Path(checkpoint_file).read_bytes()).hexdigest()
    evaluated = cells.evaluation_of(
        checkpoint_file, evaluation.read_checkpoint(checkpoint_file)[1], (), {}, ROOT / "eval_gamma_sweep.py"
    )
    return cells.cell_path(output, checkpoint_file, gamma, settings, digest, cells.evaluation_stack(),
                           evaluated.evaluator)  # fmt: skip


def test_cells_follow_a_checkpoint_copied_elsewhere_but_not_a_changed_one(runs, tmp_path):
    settings = (50, 10_000, False, False)
    original = checkpoint(runs, "continuous")
    moved = tmp_path / "elsewhere" / original.relative_to(runs)
    moved.parent.mkdir(parents=True)
    shutil.copy(original, moved)  # a new path and a new timestamp, as on another machine
    assert moved.stat().st_mtime_ns != original.stat().st_mtime_ns
    output = tmp_path / "sweep"
    assert cell_file(output, moved, 1.0, settings) == cell_file(output, original, 1.0, settings)
    changed = tmp_path / "changed" / original.relative_to(runs)
    changed.parent.mkdir(parents=True)
    changed.write_bytes(original.read_bytes() + b"\0")
    assert cell_file(output, changed, 1.0, settings) != cell_file(output, original, 1.0, settings)


def test_uniform_null_control_is_temperature_scaling(runs):
    agent, ckpt = evaluation.load_any_checkpoint(checkpoint(runs, "discrete"))
    raw = np.random.default_rng(1).normal(size=(10, 4)) * 0.1
    learned = torch.from_numpy(guided_branch(agent, ckpt, raw, 3.0)).softmax(-1)
    uniform = torch.from_numpy(guided_branch(agent, ckpt, raw, 3.0, uniform_null=True)).softmax(-1)
    with torch.no_grad():
        tempered = (3.0 * agent.actor(torch.as_tensor(raw, dtype=torch.float32))).softmax(-1)
    torch.testing.assert_close(uniform, tempered)
    assert not torch.allclose(learned, tempered)


def test_ci_against_hand_computed_values():
    # mean 3; s = sqrt(2.5) = 1.58114; t_{0.975,4} = 2.776445; half = 2.776445 * 1.58114 / sqrt(5) = 1.963243
    mean, half, low, high = episodes.mean_ci95([1, 2, 3, 4, 5])
    assert mean == 3 and half == pytest.approx(1.963243, abs=1e-6) and low == pytest.approx(3 - 1.963243, abs=1e-6)
    assert episodes.mean_ci95([500, 500, 500])[1] == 0.0
    assert math.isnan(episodes.mean_ci95([7.0])[1])
    mean, half, low, high = episodes.mean_ci95([1, 2, 3, 4, 5], method="bootstrap")
    assert mean == 3 and 1.8 <= low <= 2.2 and 3.8 <= high <= 4.2 and half == pytest.approx((high - low) / 2)


def test_summary_aggregates_per_seed_means():
    rows = [
        {"env_id": "E", "variant": "v", "train_guidance": 1.1, "cond_dropout": 0.0, "step": 100, "eval_guidance": 2.0,
         "policy": "sample", "null_branch": "learned", "seed": seed, "return": r}
        for seed, returns in [(1, [10, 20]), (2, [40, 40]), (3, [0, 60])]
        for r in returns
    ]  # fmt: skip
    (row,) = engine.summary_rows(rows)
    assert row["n_seeds"] == 3 and row["n_episodes"] == 6 and row["mean"] == round(85 / 3, 4)
    assert row["seed_means"] == "15.0000;40.0000;30.0000"
    assert row["ci95"] == pytest.approx(round(episodes.mean_ci95([15, 40, 30])[1], 4))


def sweep_args(runs, output, **overrides):
    return replace(
        sweep.Args(paths=(str(runs / "discrete"),), output=str(output), gammas=(1.0, 2.0), episodes=4), **overrides
    )


def test_resume_after_interruption_gives_same_csv(runs, tmp_path, monkeypatch):
    sweep.sweep(sweep_args(runs, tmp_path / "whole"))
    expected = (tmp_path / "whole" / "episodes.csv").read_text()

    calls = {"n": 0}
    real_run_job = engine.run_job

    def crash_after_two(job):
        calls["n"] += 1
        if calls["n"] > 2:
            raise KeyboardInterrupt
        return real_run_job(job)

    monkeypatch.setattr(engine, "run_job", crash_after_two)
    with pytest.raises(KeyboardInterrupt, match="2 of the sweep's 8 cells are finished"):
        sweep.sweep(sweep_args(runs, tmp_path / "resumed"))
    assert len(list((tmp_path / "resumed" / "cells").glob("*.csv"))) == 2  # one job is one (checkpoint, γ) cell
    assert not (tmp_path / "resumed" / "episodes.csv").exists()

    evaluated = []
    monkeypatch.setattr(engine, "run_job", lambda job: evaluated.append(job) or real_run_job(job))
    sweep.sweep(sweep_args(runs, tmp_path / "resumed"))
    assert len(evaluated) == 6  # only the cells not finished before the crash
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


def run_main(monkeypatch, capsys, argv) -> tuple[int, list[str]]:
    """main() in this process: (exit status, stderr lines)."""
    monkeypatch.setattr(sys, "argv", ["eval_gamma_sweep.py", *argv])
    with pytest.raises(SystemExit) as exit_info:
        sweep.main()
    return exit_info.value.code, capsys.readouterr().err.splitlines()


@pytest.mark.parametrize(
    "argv,message",
    [
        (["/no/such/dir"], "no such file or directory"),
        (["{empty}"], "no checkpoints"),
        (["{runs}", "--gammas", "1", "nan"], "--gammas must be"),
        (["{runs}", "--gammas", "-1"], "--gammas must be"),
        (["{runs}", "--gammas", "1e39"], "--gammas must be"),
        (["{runs}", "--gammas", "2", "1000.5"], "--gammas must be"),
        (["{runs}", "--gammas"], "--gammas needs at least one value"),
        (["{runs}", "--steps"], "--steps needs at least one value"),
        ([], "no run directories"),
        (["{runs}", "--eval-seed", "-1"], "--eval-seed"),
        (["{runs}", "--steps", "12345"], "no checkpoint at steps"),
        (["{corrupt}"], "no checkpoint could be evaluated"),
    ],
)
def test_bad_input_exits_with_one_line(runs, tmp_path, argv, message, monkeypatch, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "corrupt" / "checkpoints").mkdir(parents=True)
    (tmp_path / "corrupt" / "checkpoints" / "step_000000001.pt").write_bytes(b"\x00" * 10)
    argv = [a.format(empty=tmp_path / "empty", runs=runs / "discrete", corrupt=tmp_path / "corrupt") for a in argv]
    code, stderr = run_main(monkeypatch, capsys, [*argv, "--output", str(tmp_path / "o")])
    errors = [line for line in stderr if line.startswith("error:")]
    assert code == 2 and len(errors) == 1 and message in errors[0], stderr
    if message != "no checkpoint could be evaluated":  # rejected before anything was written
        assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_bad_input_in_a_fresh_process_is_one_line_without_traceback(runs, tmp_path):
    proc = subprocess.run(
        [*SCRIPT, str(runs / "discrete"), "--gammas", "-1", "--output", str(tmp_path / "o")],
        check=False, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [proc.stderr.strip()], proc.stderr
    assert proc.stderr.startswith("error: --gammas must be")
    proc = subprocess.run(
        [*SCRIPT, str(runs / "discrete"), "--policy", "greedy"],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "--policy" in proc.stderr  # no such option


def test_an_unwritable_output_is_refused_before_any_evaluation(runs, tmp_path, monkeypatch, capsys):
    evaluated = []
    monkeypatch.setattr(engine, "run_job", evaluated.append)
    (tmp_path / "a_file").write_text("")
    outputs = [tmp_path / "a_file" / "out"]
    if os.geteuid() != 0:  # root writes into read-only directories
        (tmp_path / "read_only").mkdir(mode=0o555)
        outputs.append(tmp_path / "read_only")
    for output in outputs:
        code, stderr = run_main(monkeypatch, capsys, [str(runs / "discrete"), "--output", str(output)])
        assert code == 2 and len(stderr) == 1 and stderr[0].startswith(f"error: cannot write to {output}"), stderr
    assert evaluated == []


def test_a_second_sweep_on_one_output_is_refused(runs, tmp_path, monkeypatch, capsys):
    output = tmp_path / "out"
    held = engine.claim_output(output)  # another sweep, as far as the lock can tell: another open file
    code, stderr = run_main(monkeypatch, capsys, [str(runs / "discrete"), "--output", str(output), "--episodes", "2"])
    assert code == 2 and len(stderr) == 1 and stderr[0].startswith(f"error: {output} is in use by another sweep")
    assert not list((output / "cells").iterdir())
    held.close()
    sweep.sweep(sweep_args(runs, output, gammas=(1.0,), episodes=2))  # free again once its holder is gone


def test_a_plain_tensor_file_is_skipped_without_a_warning(runs, tmp_path):
    bad = tmp_path / "tensor" / "checkpoints"
    bad.mkdir(parents=True)
    torch.save(torch.zeros(3), bad / "step_000000100.pt")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        paths = (str(runs / "discrete"), str(tmp_path / "tensor"))
        out = sweep.sweep(sweep_args(runs, tmp_path / "out", paths=paths, gammas=(1.0,)))
    assert [str(w.message) for w in caught if issubclass(w.category, UserWarning)] == []
    (skipped,) = list(csv.DictReader((out / "skipped.csv").read_text().splitlines()))
    assert "step_000000100.pt" in skipped["reason"] and "not a PGG checkpoint" in skipped["reason"]


# --- configurations: never pool different experiments -------------------------------------------------


def test_config_label_names_every_training_argument_that_differs(runs):
    _, ckpt = evaluation.read_checkpoint(checkpoint(runs, "discrete"))
    assert identity.config_label(ckpt) == "pgg_g1.1 total_timesteps=4096"  # not seed, checkpoint_interval, output_dir
    _, other_lr = evaluation.read_checkpoint(max((runs / "discrete_lr").rglob("step_*.pt")))
    assert identity.config_label(other_lr) == "pgg_g1.1 learning_rate=0.002 total_timesteps=4096"
    # An older checkpoint lacks arguments added since: they count as their defaults.
    old_args = {
        k: v for k, v in ckpt["args"].items() if k not in ("total_timesteps", "ent_coef", "resume", "overwrite")
    }
    assert identity.config_label({**ckpt, "args": old_args}) == "pgg_g1.1"
    defaults = {
        **dataclasses.asdict(ppo_pgg_discrete.Args()),
        "seed": 7,
        "run_name": "x",
        "torch_threads": 2,
        "compile": True,
    }
    assert identity.config_label({**ckpt, "args": defaults}) == "ppo"
    assert (
        identity.config_label({**ckpt, "args": {**defaults, "cond_dropout": 0.1, "anneal_lr": False}})
        == "pgg_drop0.1 anneal_lr=False"
    )
    # MuJoCo tasks carry the simulator's version where the checkpoint records it; CartPole does not run on it.
    assert "mujoco" not in identity.config_label({**ckpt, "versions": {"mujoco": "2.3.7"}})
    _, hopper = evaluation.read_checkpoint(checkpoint(runs, "continuous"))
    hopper_label = "pgg_g1.1 num_minibatches=8 num_steps=1024 total_timesteps=2048 update_epochs=2"
    assert identity.config_label({**hopper, "versions": {"mujoco": "3.1.6"}}) == hopper_label + " mujoco=3.1.6"
    # A format-1 checkpoint records no versions: never pooled with runs whose stack is known.
    assert (
        identity.config_label({k: v for k, v in hopper.items() if k != "versions"})
        == hopper_label + " versions=unknown"
    )


def test_runs_of_one_seed_number_in_different_configurations_stay_apart(runs, tmp_path):
    """The issue's case: seed 1 at the default learning rate and seed 1 at 0.002, swept together."""
    out = sweep.sweep(sweep_args(runs, tmp_path / "out", paths=(str(runs / "discrete"), str(runs / "discrete_lr"))))
    summary = list(csv.DictReader((out / "summary.csv").read_text().splitlines()))
    assert len(summary) == 2 * 2 * 2  # steps × γ × configurations
    by_config = {(r["config"], r["step"], r["eval_guidance"]): r for r in summary}
    for (config, step, gamma), row in by_config.items():
        assert row["n_seeds"] == ("1" if "learning_rate=0.002" in config else "2")
        assert row["n_episodes"] == str(4 * int(row["n_seeds"]))
    episodes = list(csv.DictReader((out / "episodes.csv").read_text().splitlines()))
    configs = [r["config"] for r in episodes]  # both runs of seed 1 are named CartPole-v1__ppo_pgg__g1.1__p0__s1
    assert configs.count("pgg_g1.1 total_timesteps=4096") == 32
    assert configs.count("pgg_g1.1 learning_rate=0.002 total_timesteps=4096") == 16
    alone = sweep.sweep(sweep_args(runs, tmp_path / "alone", paths=(str(runs / "discrete_lr"),)))
    for row in csv.DictReader((alone / "summary.csv").read_text().splitlines()):
        assert by_config[(row["config"], row["step"], row["eval_guidance"])]["mean"] == row["mean"]


def test_two_runs_of_one_configuration_and_seed_are_an_error_naming_both(runs, tmp_path, monkeypatch, capsys):
    seed_1 = next(p for p in (runs / "discrete").iterdir() if p.name.endswith("__s1"))
    copy = tmp_path / "copy" / "renamed_run"
    shutil.copytree(seed_1, copy)
    code, stderr = run_main(
        monkeypatch, capsys, [str(runs / "discrete"), str(tmp_path / "copy"), "--output", str(tmp_path / "o")]
    )
    assert code == 2 and len(stderr) == 1 and "two runs of one experiment" in stderr[0], stderr
    assert str(seed_1) in stderr[0] and str(copy) in stderr[0]
    assert not list((tmp_path / "o" / "cells").iterdir())  # refused before evaluating anything


def test_summary_keeps_configurations_apart_and_reads_rows_without_config():
    base = {"env_id": "E", "variant": "ppo", "train_guidance": 1.0, "cond_dropout": 0.0, "step": 100,
            "eval_guidance": 1.0, "policy": "sample", "null_branch": "learned"}  # fmt: skip
    rows = [
        {**base, "run": "a", "seed": 1, "episode": 0, "return": 10.0},  # an old sweep's row: no config column
        {**base, "run": "b", "seed": 2, "episode": 0, "return": 20.0, "config": "ppo"},
        {**base, "run": "c", "seed": 1, "episode": 0, "return": 99.0, "config": "ppo learning_rate=0.002"},
    ]
    summary = engine.summary_rows(rows)
    assert [(r["config"], r["n_seeds"], r["mean"]) for r in summary] == [
        ("ppo", 2, 15.0),
        ("ppo learning_rate=0.002", 1, 99.0),
    ]
    with pytest.raises(files.InputError, match="runs a and d would both count as seed 1"):
        engine.summary_rows([*rows, {**base, "run": "d", "seed": 1, "episode": 1, "return": 0.0}])
    with pytest.raises(files.InputError, match="episode 0 of run a .* appears twice"):
        engine.summary_rows([*rows, rows[0]])


# --- a cell is named by the bytes it evaluated ---------------------------------------------------------


def test_a_cell_is_named_by_the_bytes_it_evaluated(runs, tmp_path, monkeypatch):
    seed_1 = next(p for p in (runs / "discrete").iterdir() if p.name.endswith("__s1"))
    shutil.copytree(seed_1, tmp_path / "runs" / seed_1.name)
    target = max((tmp_path / "runs").rglob("step_*.pt"))
    evaluated_bytes = target.read_bytes()
    replacement = max((runs / "discrete_lr").rglob("step_*.pt")).read_bytes()  # another run's weights
    real_run_job = engine.run_job

    def rerun_rewrites_the_file_meanwhile(job):
        result = real_run_job(job)
        target.write_bytes(replacement)  # a rerun of the run name replaced it while the job ran
        return result

    monkeypatch.setattr(engine, "run_job", rerun_rewrites_the_file_meanwhile)
    args = sweep_args(runs, tmp_path / "out", paths=(str(target),), gammas=(2.0,))
    sweep.sweep(args)
    digest = hashlib.sha1(evaluated_bytes).hexdigest()
    settings = engine.settings_of(args)
    evaluated_cell = cell_file(tmp_path / "out", target, 2.0, settings, digest)
    assert [p.name for p in (tmp_path / "out" / "cells").iterdir()] == [evaluated_cell.name]
    assert "learning_rate=0.002" not in evaluated_cell.read_text()
    # The file now holds other bytes: a rerun evaluates them, into a cell of their own.
    evaluated = []
    monkeypatch.setattr(engine, "run_job", lambda job: evaluated.append(job) or real_run_job(job))
    sweep.sweep(args)
    assert len(evaluated) == 1 and cell_file(tmp_path / "out", target, 2.0, settings).exists()
    assert "learning_rate=0.002" in (tmp_path / "out" / "episodes.csv").read_text()


def test_a_checkpoint_rewritten_during_its_sweep_is_reported_not_mixed(runs, tmp_path, monkeypatch):
    seed_1 = next(p for p in (runs / "discrete").iterdir() if p.name.endswith("__s1"))
    shutil.copytree(seed_1, tmp_path / "runs" / seed_1.name)
    target = max((tmp_path / "runs").rglob("step_*.pt"))
    replacement = max((runs / "discrete_lr").rglob("step_*.pt")).read_bytes()
    real_run_job = engine.run_job

    def rewrite_after_the_first_cell(job):
        result = real_run_job(job)
        target.write_bytes(replacement)
        return result

    monkeypatch.setattr(engine, "run_job", rewrite_after_the_first_cell)
    seed_2 = max((runs / "discrete").rglob("step_*.pt"))
    out = sweep.sweep(sweep_args(runs, tmp_path / "out", paths=(str(target), str(seed_2))))
    assert len(list((out / "cells").iterdir())) == 4  # every cell kept, each named by what it evaluated
    (skipped,) = list(csv.DictReader((out / "skipped.csv").read_text().splitlines()))
    assert str(target) in skipped["reason"] and "rewritten during the sweep" in skipped["reason"]
    runs_reported = {r["run"] for r in csv.DictReader((out / "episodes.csv").read_text().splitlines())}
    assert runs_reported == {seed_2.parent.parent.name}


# --- interruptions -------------------------------------------------------------------------------------


@pytest.fixture
def long_sweep(runs):
    """Starts a sweep that runs for tens of seconds, in a session of its own (as if in its own
    terminal); whatever of it is left at the end of the test is killed."""
    started = []

    def start(output: Path, workers: int) -> subprocess.Popen:
        gammas = ["1", "2", "3", "4", "5", "6", "7", "8"]
        argv = [*SCRIPT, str(runs / "discrete"), "--output", str(output), "--episodes", "1000", "--gammas", *gammas,
                "--workers", str(workers)]  # fmt: skip
        started.append(subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                        start_new_session=True, preexec_fn=default_sigint))  # fmt: skip
        return started[-1]

    yield start
    for proc in started:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # its session: the sweep and any worker left
        except ProcessLookupError:
            pass
        proc.wait()


def wait_for(condition, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    deadline = time.time() + timeout
    while not condition():
        assert proc.poll() is None, f"the sweep ended early: {proc.stderr.read()}"
        assert time.time() < deadline, "timed out"
        time.sleep(0.02)


def children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_exits_130_with_one_line_and_keeps_finished_cells(long_sweep, tmp_path, workers):
    output = tmp_path / "out"
    proc = long_sweep(output, workers)
    wait_for(lambda: (output / "cells").is_dir() and any((output / "cells").glob("*.csv")), proc)
    os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the whole process group
    _, stderr = proc.communicate(timeout=60)
    kept = len(list((output / "cells").glob("*.csv")))
    assert proc.returncode == 130 and "Traceback" not in stderr and "Error" not in stderr, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"interrupted: {kept} of the sweep's 32 cells are finished in {output / 'cells'}"), last
    assert 1 <= kept < 32


def test_stopping_the_pool_ends_its_manager_thread_before_returning():
    """Python 3.11's exit hook writes to the pool manager thread's wakeup pipe without the lock under which
    that thread closes it: a thread still ending at exit (Ctrl-C under load) made the sweep end with "Exception
    ignored ... OSError: [Errno 9] Bad file descriptor". stop_pool returns only when the thread is gone."""
    from concurrent.futures.process import _ExecutorManagerThread

    for _ in range(3):
        pool, _, processes = start_pool(2, engine.run_job, [])
        stop_pool(pool, processes)
        assert not [t for t in threading.enumerate() if isinstance(t, _ExecutorManagerThread)]
        assert not any(process.is_alive() for process in processes.values())


@pytest.mark.slow
def test_a_killed_sweep_leaves_no_worker_and_no_lock(long_sweep, tmp_path):
    output = tmp_path / "out"
    proc = long_sweep(output, workers=2)
    wait_for(lambda: len(children(proc.pid)) >= 2 and any((output / "cells").glob("*.csv")), proc)
    workers = children(proc.pid)
    proc.kill()  # SIGKILL: the parent gets no chance to end its workers
    proc.wait()
    deadline = time.time() + 10
    while any(map(alive, workers)) and time.time() < deadline:
        time.sleep(0.05)
    survivors = [pid for pid in workers if alive(pid)]
    for pid in survivors:
        os.kill(pid, signal.SIGKILL)
    assert survivors == []
    stderr = proc.stderr.read()
    assert "Traceback" not in stderr and "BrokenPipeError" not in stderr, stderr
    engine.claim_output(output).close()  # the lock died with its holder


# --- videos of the knob ----------------------------------------------------------------------------


def frame_count(path: Path) -> int:
    import imageio.v3 as iio

    return sum(1 for _ in iio.imiter(path))


@pytest.mark.slow
def test_video_records_the_same_episode_at_each_gamma(runs, tmp_path):
    """One video per γ of episode k (its reset seed and noise, as in a sweep cell), each frame of it,
    and a side-by-side video as long as the longest. The recorded episode is the sweep cell's episode k:
    its length fixes the frame count."""
    pytest.importorskip("moviepy", reason="--video needs the [video] extra")
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    path = checkpoint(runs, "discrete")
    args = sweep.Args(paths=(str(path),), gammas=(1.0, 5.0), video=str(tmp_path / "videos"), video_episode=2)
    written = sweep.record_videos(args)
    assert [p.name for p in written] == ["gamma_1.mp4", "gamma_5.mp4", "side_by_side.mp4"]
    agent, ckpt = evaluation.load_any_checkpoint(path)
    policy = evaluation.GuidedPolicy(agent, ckpt)
    lengths = [
        int(evaluation.evaluate_cell(policy, ckpt, gamma, args.episodes, args.eval_seed, False)["length"][2])
        for gamma in (1.0, 5.0)
    ]
    assert [frame_count(p) for p in written] == [lengths[0] + 1, lengths[1] + 1, max(lengths) + 1]
    assert not list((tmp_path / "videos").glob(".*tmp*"))


@pytest.mark.slow
def test_video_of_several_checkpoints_is_one_line_of_error(runs, tmp_path):
    proc = subprocess.run(
        [*SCRIPT, str(runs / "discrete"), "--video", str(tmp_path / "v")],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "--video records one checkpoint; 4 found" in lines[0]
    assert not (tmp_path / "v").exists()


def test_video_of_a_mujoco_checkpoint_where_a_gl_backend_renders(runs, tmp_path):
    pytest.importorskip("moviepy", reason="--video needs the [video] extra")
    env = dict(os.environ, MUJOCO_GL="osmesa", PYOPENGL_PLATFORM="osmesa")
    probe = subprocess.run([sys.executable, "-c", "import gymnasium as g; e = g.make('Hopper-v4', render_mode='rgb_array'); e.reset(); e.render()"],
                           check=False, capture_output=True, env=env, timeout=120)  # fmt: skip
    if probe.returncode:
        pytest.skip("MuJoCo cannot render headless here (apt-get install libosmesa6 for MUJOCO_GL=osmesa)")
    proc = subprocess.run([*SCRIPT, str(checkpoint(runs, "continuous")), "--gammas", "1", "1.5", "--video", str(tmp_path / "v")],
                          check=False, capture_output=True, text=True, env=env, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert frame_count(tmp_path / "v" / "side_by_side.mp4") >= max(
        frame_count(tmp_path / "v" / f"gamma_{g}.mp4") for g in ("1", "1.5")
    )


def test_cached_cells_take_todays_config_label(runs, tmp_path, monkeypatch):
    """A cell keeps its numbers across reruns, but its rows carry the label the checkpoint has today:
    a cell written under an older labelling rule must not split its run into two configurations."""
    args = sweep_args(runs, tmp_path / "out")
    sweep.sweep(args)
    fresh = read_csv(tmp_path / "out" / "episodes.csv")
    for cell in (tmp_path / "out" / "cells").glob("*.csv"):
        rows = cells.read_cell(cell, args.episodes)
        cells.write_cell(cell, [{**row, "config": "pgg_g1.1 stale=1"} for row in rows])  # whole, checksums and all
    evaluated = []
    monkeypatch.setattr(engine, "run_job", evaluated.append)
    sweep.sweep(args)
    assert evaluated == [] and read_csv(tmp_path / "out" / "episodes.csv") == fresh


@pytest.mark.slow
@pytest.mark.parametrize("table", ["discrete", "continuous"])
def test_the_shipped_agents_load_and_sweep(table, tmp_path):
    """The agents folder of a table: pickle-free, without resume state, each one a (run, step) of the
    table's episodes.csv, listed in its README, and sweepable as they are (two episodes here; the README's
    full re-sweep reproduces the committed episodes.csv on the machine that trained them)."""
    agents = ROOT / "results" / table / "agents"
    files = sorted(agents.rglob("step_*.pt"))
    with open(ROOT / "results" / table / "episodes.csv", newline="") as f:
        swept = {(r["run"], int(r["step"])) for r in csv.DictReader(f)}
    shipped = {(path.parent.parent.name, checkpoint_step(path)) for path in files}
    assert files and shipped <= swept
    readme = (agents / "README.md").read_text()
    assert all(f"| {run} |" in readme for run, _ in shipped)
    agent, ckpt = evaluation.load_any_checkpoint(files[0])
    assert "resume" not in ckpt and ckpt["code"]["commit"]
    assert agent.null_obs.shape == (ckpt["obs_dim"],)
    output = sweep.sweep(sweep.Args(paths=(str(files[-1]),), gammas=(1.0, 1.1), episodes=2, output=str(tmp_path / "s")))
    rows = read_csv(output / "episodes.csv")
    assert len(rows) == 4 and all(math.isfinite(float(r["return"])) for r in rows)
