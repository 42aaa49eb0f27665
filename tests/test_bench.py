import subprocess
import sys
import threading

import numpy as np
import pytest

import ppo_pgg_discrete as pgg
from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_speed  # noqa: E402


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
    assert all(a != b for a, b in zip(workers, workers[1:]))  # A, B, A, B, A, B
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


def test_sweep_checkpoints_are_matched_to_their_env_and_bad_ones_are_one_line_of_error(tmp_path):
    args = tiny_run(1.1)
    args.output_dir, args.checkpoint_interval = str(tmp_path), 10**9
    pgg.train(args, pgg.prepare_run_dir(args))
    (checkpoint,) = tmp_path.rglob("step_*.pt")
    assert bench_speed.checkpoints_by_env([str(checkpoint)]) == {"CartPole-v1": checkpoint}

    not_a_checkpoint = tmp_path / "notes.txt"
    not_a_checkpoint.write_text("not a checkpoint")
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_speed.py"), "--sweep-checkpoints", str(not_a_checkpoint)],
        capture_output=True, text=True,
    )  # fmt: skip
    assert out.returncode != 0
    assert out.stderr.startswith("error: --sweep-checkpoints") and len(out.stderr.strip().splitlines()) == 1
