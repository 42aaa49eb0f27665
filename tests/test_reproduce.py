import os
import signal
import subprocess
import sys
import time
from dataclasses import replace

import pytest

import reproduce
from conftest import ROOT

TINY = ["--total-timesteps", "2048", "--checkpoint-interval", "1024", "--seeds", "2", "--variants", "ppo", "pgg_g1.1",
        "--gammas", "1", "2", "--episodes", "3"]  # fmt: skip


def tiny_args(tmp_path, name, **overrides) -> reproduce.Args:
    args = reproduce.Args(
        preset="quick", total_timesteps=2048, checkpoint_interval=1024, seeds=2, variants=("ppo", "pgg_g1.1"),
        gammas=(1.0, 2.0), episodes=3, workers=2, root=str(tmp_path / name / "runs"),
        results=str(tmp_path / name / "results"),
    )  # fmt: skip
    return replace(args, **overrides)


@pytest.fixture(scope="module")
def local_results(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("reproduce")
    assert reproduce.reproduce(tiny_args(tmp_path, "local")) == 0
    return tmp_path / "local" / "results"


def test_quick_preset_runs_end_to_end_locally(local_results):
    table = (local_results / "table_discrete.md").read_text()
    assert "| Method | CartPole-v1 |" in table and "| PPO |" in table and "| pgg_g1.1 |" in table
    episodes = (local_results / "episodes.csv").read_text().splitlines()
    assert len(episodes) - 1 == 2 * 2 * 2 * 2 * 3  # seeds × variants × checkpoints × γ × episodes
    for name in ("fig_discrete_pgg_g1.1.png", "learning_curves.png", "compare_paper.md", "table_discrete.tex"):
        assert (local_results / name).exists(), name


def test_quick_preset_through_submitit_local_executor(local_results, tmp_path):
    assert reproduce.reproduce(tiny_args(tmp_path, "submitit", executor="submitit-local")) == 0
    results = tmp_path / "submitit" / "results"
    assert (results / "episodes.csv").read_text() == (local_results / "episodes.csv").read_text()
    assert (results / "table_discrete.md").exists()


def test_killed_launcher_resumes_without_retraining(local_results, tmp_path):
    root = tmp_path / "killed" / "runs"
    command = [sys.executable, str(ROOT / "reproduce.py"), *TINY, "--workers", "1", "--root", str(root),
               "--results", str(tmp_path / "killed" / "results")]  # fmt: skip
    launcher = subprocess.Popen(command, start_new_session=True, stderr=subprocess.DEVNULL, cwd=tmp_path)
    finals = lambda: sorted(root.glob("*/checkpoints/step_000002048.pt"))  # noqa: E731
    deadline = time.time() + 300
    while len(finals()) < 1 and time.time() < deadline:
        time.sleep(0.2)
    os.killpg(launcher.pid, signal.SIGKILL)  # the launcher and the run in flight, as a hard kill would
    launcher.wait()
    finished = {path: path.stat().st_mtime_ns for path in finals()}
    assert 1 <= len(finished) < 4

    rerun = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    assert f"{len(finished)} already trained" in rerun.stderr
    assert all(path.stat().st_mtime_ns == mtime for path, mtime in finished.items())  # not retrained
    assert len(finals()) == 4
    episodes = (tmp_path / "killed" / "results" / "episodes.csv").read_text()
    assert episodes == (local_results / "episodes.csv").read_text()


def test_failed_run_is_reported_and_others_finish(tmp_path, monkeypatch):
    real_command = reproduce.RunSpec.command

    def broken_for_seed_two(spec):
        cmd = real_command(spec)
        return cmd + ["--guidance", "-1"] if spec.seed == 2 else cmd

    monkeypatch.setattr(reproduce.RunSpec, "command", broken_for_seed_two)
    args = tiny_args(tmp_path, "failing", variants=("ppo",))
    assert reproduce.reproduce(args) == 1
    log = tmp_path / "failing" / "runs" / "logs" / "CartPole-v1__ppo__s2.log"
    assert "--guidance must be a number in [0, 1000]" in log.read_text()
    assert (tmp_path / "failing" / "runs" / "CartPole-v1__ppo__s1" / "checkpoints" / "step_000002048.pt").exists()


def test_compile_flag_reaches_every_training_command(tmp_path):
    for compile_ in (False, True):
        specs = reproduce.grid(tiny_args(tmp_path, "compile", compile=compile_))
        assert len(specs) == 4 and all(("--compile" in spec.command()) == compile_ for spec in specs)
