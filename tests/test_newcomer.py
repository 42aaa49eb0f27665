"""What a newcomer broke (issue 37): a killed sweep worker, tasks outside the paper, runs of another grid,
two launchers on one root, a hand-edited episodes.csv, the exit-code rule and the one-line errors."""

import argparse
import ctypes.util
import errno
import os
import shutil
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT, one_line_error, run_main, run_script
from test_plots import episode_rows, run_cli, write_episodes

import eval_gamma_sweep as sweep
import plot_results
import ppo_pgg_continuous
import ppo_pgg_discrete
import reproduce
from pgg_utils import bc_null, checkpoints, checks, files
from pgg_utils.files import lock_directory

FIXTURES = Path(__file__).resolve().parent / "fixtures"
FORMAT_2 = FIXTURES / "cartpole_format2" / "checkpoints" / "step_000000512.pt"


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("error:")]


# --- 1. a SIGKILLed sweep worker ------------------------------------------------------------------------

# The sweep's command, with its worker SIGKILLing itself when it takes up the γ = 5 cell (as the OOM
# killer would kill it): no hang, one line, exit 1, the other cells kept.
DYING_WORKER = """
import os, signal, sys
import eval_gamma_sweep as sweep
from pgg_utils import sweep as engine
real_run_job = engine.run_job
def killed_at_gamma_5(job):
    if job.gamma == 5.0:
        os.kill(os.getpid(), signal.SIGKILL)
    return real_run_job(job)
engine.run_job = killed_at_gamma_5
sys.argv = ["eval_gamma_sweep.py", *sys.argv[1:]]
sweep.main()
"""


@pytest.mark.slow
def test_a_sigkilled_worker_ends_the_sweep_with_one_line_and_a_rerun_completes_it(tmp_path):
    flags = [str(FORMAT_2), "--gammas", "1", "2", "5", "10", "--episodes", "4", "--workers", "2"]
    start = time.time()
    killed = subprocess.run([sys.executable, "-c", DYING_WORKER, *flags, "--output", str(tmp_path / "out")],
                            capture_output=True, text=True, cwd=ROOT, timeout=60)  # fmt: skip
    assert time.time() - start < 60
    (line,) = error_lines(killed.stderr)
    assert killed.returncode == 1 and "Traceback" not in killed.stderr, killed.stderr
    assert "a sweep worker died (pid " in line and "was killed by SIGKILL" in line, line
    kept = len(list((tmp_path / "out" / "cells").glob("*.csv")))  # the other worker's cell in flight may be lost
    assert 1 <= kept <= 3 and f"{kept} of the sweep's 4 cells are finished" in line, line
    assert "rerun the same command" in line, line
    rerun = subprocess.run([sys.executable, str(ROOT / "eval_gamma_sweep.py"), *flags, "--output", str(tmp_path / "out")],
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    assert rerun.returncode == 0, rerun.stderr
    assert f"4 cells, {kept} already done" in rerun.stderr
    clean = sweep.sweep(sweep.Args(paths=(str(FORMAT_2),), output=str(tmp_path / "clean"), gammas=(1.0, 2.0, 5.0, 10.0),
                                   episodes=4))  # fmt: skip
    for name in ("episodes.csv", "summary.csv"):
        assert (tmp_path / "out" / name).read_text() == (clean / name).read_text()


# --- 2. tasks the paper did not run ---------------------------------------------------------------------


def tiny_grid(tmp_path, name: str, **overrides) -> reproduce.Args:
    args = reproduce.Args(preset="quick", total_timesteps=1024, checkpoint_interval=512, seeds=1, variants=("ppo",),
                          gammas=(1.0, 2.0), episodes=2, workers=1, root=str(tmp_path / "runs"),
                          results=str(tmp_path / name))  # fmt: skip
    return replace(args, **overrides)


@pytest.mark.slow
def test_reproduce_on_a_task_outside_the_paper_ends_with_its_tables_and_agents(tmp_path, capsys):
    assert reproduce.reproduce(tiny_grid(tmp_path, "results", envs=("MountainCar-v0",))) == 0
    results = tmp_path / "results"
    assert "| Method | MountainCar-v0 |" in (results / "table_discrete.md").read_text()
    assert "| MountainCar-v0__ppo__s1 | MountainCar-v0 | ppo | 1 |" in (results / "agents" / "README.md").read_text()
    assert not (results / "compare_paper.md").exists()
    err = capsys.readouterr().err
    assert "none of the swept envs (MountainCar-v0) is in the paper's tables" in err and "results in" in err


@pytest.mark.slow
def test_compare_paper_on_tasks_outside_the_paper_is_a_note_and_exit_0(tmp_path):
    target = tmp_path / "episodes.csv"  # not in the paper, and not a gymnasium task: its rows say how it acts
    write_episodes(target, episode_rows({("MyEnv-v0", "ppo", 1000, 1.0): [1.0, 2.0]}, action_space="discrete"))
    done = run_cli(target, "--output", tmp_path / "out", "--compare-paper")
    assert done.returncode == 0 and not error_lines(done.stderr), done.stderr
    assert "note: none of the swept envs (MyEnv-v0) is in the paper's tables" in done.stderr
    assert (tmp_path / "out" / "table_discrete.md").exists() and not (tmp_path / "out" / "compare_paper.md").exists()


# --- 3. runs of another grid ----------------------------------------------------------------------------


@pytest.mark.slow
def test_runs_trained_with_other_arguments_are_refused_and_never_swept(tmp_path, capsys):
    assert reproduce.reproduce(tiny_grid(tmp_path, "first")) == 0  # s1, 1,024 steps
    second = tiny_grid(tmp_path, "second", seeds=2, total_timesteps=2048, checkpoint_interval=1024)
    assert reproduce.reproduce(second) == 1  # s1 is refused ("other arguments"), s2 trains
    err = capsys.readouterr().err
    assert "FAILED CartPole-v1__ppo__s1" in err
    assert (
        "not swept, trained with other arguments than this grid's: CartPole-v1__ppo__s1 (total_timesteps 1024 -> 2048)"
        in err
    )
    swept = {row["run"] for row in files.read_csv(tmp_path / "second" / "episodes.csv")}
    assert swept == {"CartPole-v1__ppo__s2"}
    assert "**1,024 Steps**" in (tmp_path / "second" / "table_discrete.md").read_text()


# --- 4. two launchers on one root -----------------------------------------------------------------------

QUICK = ["--seeds", "1", "--variants", "ppo", "--total-timesteps", "1024", "--checkpoint-interval", "512",
         "--gammas", "1", "--episodes", "2", "--workers", "1"]  # fmt: skip


def test_a_second_launcher_on_a_root_in_use_is_refused_in_one_line(tmp_path):
    root = tmp_path / "runs"
    root.mkdir()
    first = lock_directory(root, "another reproduce.py")  # as the first launcher holds it, training
    try:
        second = run_main(reproduce, *QUICK, "--root", str(root), "--results", str(tmp_path / "results"))
    finally:
        first.close()
    line = one_line_error(second)
    assert line == (f"error: {root} is in use by another reproduce.py (pid {os.getpid()}); wait for it to finish or "
                    "choose another --root")  # fmt: skip
    assert [p.name for p in root.iterdir()] == [".lock"]  # nothing trained


# --- 5. a hand-edited episodes.csv ------------------------------------------------------------------------


@pytest.mark.parametrize("value,message", [
    ("abc", "return 'abc' is not a number"),
    ("nan", "return 'nan' is not finite"),
    ("inf", "return 'inf' is not finite"),
    ("99999", "return 99999 is outside what CartPole-v1 allows, [0, 500]"),
    ("-1", "return -1 is outside what CartPole-v1 allows, [0, 500]"),
])  # fmt: skip
def test_an_edited_return_is_one_line_naming_the_line_and_exit_2(tmp_path, value, message):
    rows = episode_rows({("CartPole-v1", "ppo", 1000, 1.0): [100.0, 200.0, 300.0]})
    rows[3]["return"] = value
    write_episodes(tmp_path / "episodes.csv", rows)
    done = run_cli(tmp_path / "episodes.csv", "--output", tmp_path / "out")
    assert one_line_error(done) == f"error: {tmp_path / 'episodes.csv'}, line 5: {message}"
    assert not (tmp_path / "out" / "table_discrete.md").exists()


def test_an_edited_step_is_one_line(tmp_path):
    rows = episode_rows({("CartPole-v1", "ppo", 1000, 1.0): [100.0, 200.0]})
    rows[0]["step"] = "1e3"
    write_episodes(tmp_path / "episodes.csv", rows)
    done = run_cli(tmp_path / "episodes.csv", "--output", tmp_path / "out")
    assert one_line_error(done) == f"error: {tmp_path / 'episodes.csv'}, line 2: step '1e3' is not an integer"


# --- 6. one exit-code rule: 2 bad input, 1 failed at run time, 130 Ctrl-C --------------------------------


def full_disk_main(script: str, tmp_path: Path) -> tuple[str, list]:
    """A script's main, argv and the output it should name, for a disk that is full from the start."""
    sweep_csv = tmp_path / "sweep" / "episodes.csv"
    write_episodes(sweep_csv, episode_rows({("CartPole-v1", "ppo", 1000, 1.0): [100.0, 200.0]}))
    return {
        "ppo_pgg_discrete.py": (ppo_pgg_discrete.main, ["--total-timesteps", "512", "--num-steps", "128",
                                                        "--checkpoint-interval", "512", "--output-dir", str(tmp_path / "runs"),
                                                        "--run-name", "full"], tmp_path / "runs" / "full" / "args.json"),
        "eval_gamma_sweep.py": (sweep.main, [str(FORMAT_2), "--gammas", "1", "--episodes", "2", "--output",
                                             str(tmp_path / "out")], tmp_path / "out" / "cells"),
        "plot_results.py": (plot_results.main, [str(sweep_csv), "--output", str(tmp_path / "out")], tmp_path / "out"),
    }[script]  # fmt: skip


@pytest.mark.parametrize("script", ["ppo_pgg_discrete.py", "eval_gamma_sweep.py", "plot_results.py"])
def test_a_full_disk_is_exit_1_naming_the_file_in_every_script(tmp_path, monkeypatch, capsys, script):
    def rename_on_a_full_disk(source, target):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    main, argv, named = full_disk_main(script, tmp_path)
    monkeypatch.setattr(files.os, "replace", rename_on_a_full_disk)
    monkeypatch.setattr(sys, "argv", [script, *argv])
    with pytest.raises(SystemExit) as exit_info:
        main()
    errors = error_lines(capsys.readouterr().err)
    assert exit_info.value.code == 1 and len(errors) == 1, errors
    assert errors[0].startswith(f"error: cannot write {named}") and errors[0].endswith("No space left on device"), (
        errors
    )


@pytest.mark.parametrize("script", ["ppo_pgg_discrete.py", "eval_gamma_sweep.py", "plot_results.py", "reproduce.py"])
def test_an_output_folder_that_is_a_file_is_bad_input_exit_2(tmp_path, script):
    taken = tmp_path / "taken"
    taken.write_text("")
    flags = {"ppo_pgg_discrete.py": ["--output-dir", str(taken)],
             "eval_gamma_sweep.py": [str(FORMAT_2), "--output", str(taken)],
             "plot_results.py": [str(FORMAT_2.parent), "--output", str(taken)],
             "reproduce.py": [*QUICK, "--root", str(taken)]}[script]  # fmt: skip
    if script == "plot_results.py":
        write_episodes(
            tmp_path / "sweep" / "episodes.csv", episode_rows({("CartPole-v1", "ppo", 1000, 1.0): [1.0, 2.0]})
        )
        flags[0] = str(tmp_path / "sweep")
    module = {"ppo_pgg_discrete.py": ppo_pgg_discrete, "eval_gamma_sweep.py": sweep, "plot_results.py": plot_results,
              "reproduce.py": reproduce}[script]  # fmt: skip
    line = one_line_error(run_main(module, *flags))
    assert str(taken) in line, line


# --- 7. one line of error where the scripts write the error ----------------------------------------------


@pytest.mark.skipif(shutil.which("srun") is not None, reason="Slurm is installed here")
def test_slurm_without_slurm_is_one_line_before_anything_is_trained(tmp_path):
    done = run_main(reproduce, *QUICK, "--executor", "slurm", "--root", str(tmp_path / "runs"))
    assert "--executor slurm needs Slurm (srun and sbatch on PATH)" in one_line_error(done)
    assert not (tmp_path / "runs").exists()


class MultiDiscreteEnv(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.MultiDiscrete([2, 3])

    def __init__(self, render_mode=None):
        self.render_mode = render_mode


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_an_action_space_neither_script_trains_gets_no_circular_advice(kind):
    gym.register("NewcomerMultiDiscrete-v0", entry_point=MultiDiscreteEnv)
    try:
        error = checks.env_error("NewcomerMultiDiscrete-v0", kind)
    finally:
        del gym.registry["NewcomerMultiDiscrete-v0"]
    assert error == ("NewcomerMultiDiscrete-v0 has a MultiDiscrete action space; neither script trains it "
                     "(ppo_pgg_discrete.py: Discrete, ppo_pgg_continuous.py: Box)")  # fmt: skip


def test_a_file_of_python_objects_is_refused_without_torchs_advice_to_unpickle_it(tmp_path):
    foreign = tmp_path / "run" / "checkpoints" / "step_000000512.pt"
    foreign.parent.mkdir(parents=True)
    torch.save({"model": argparse.Namespace()}, foreign)
    done = run_main(sweep, str(foreign), "--video", str(tmp_path / "videos"))
    line = one_line_error(done)
    assert "not a PGG checkpoint (it holds Python objects" in line and "weights_only" not in line, line


@pytest.mark.slow
@pytest.mark.skipif(ctypes.util.find_library("OSMesa") is not None, reason="OSMesa is installed here")
def test_osmesa_without_its_library_names_the_package(tmp_path):
    env = dict(os.environ, MUJOCO_GL="osmesa", PYOPENGL_PLATFORM="osmesa")
    done = run_script("ppo_pgg_continuous.py", "--env-id", "Hopper-v4", "--capture-video", "--output-dir",
                      str(tmp_path), env=env)  # fmt: skip
    assert "osmesa needs apt-get install libosmesa6" in one_line_error(done)


# --- 8. a namespaced env id (issue 46) -------------------------------------------------------------------

NAMESPACED_MODULE = """
import gymnasium as gym
import numpy as np


class Line(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, render_mode=None):
        self.render_mode = render_mode

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.full(2, float(action) - 0.5, np.float32), float(action), False, False, {}


gym.register("ns46/Line-v0", entry_point=Line, max_episode_steps=20)
"""


@pytest.mark.slow
def test_reproduce_trains_and_sweeps_a_namespaced_id_in_one_directory_per_run(tmp_path, monkeypatch):
    """`module:namespace/Env-v0` ids: the run name replaces ':' and '/' by '-', one path component."""
    (tmp_path / "newcomer46.py").write_text(NAMESPACED_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    assert reproduce.reproduce(tiny_grid(tmp_path, "results", envs=("newcomer46:ns46/Line-v0",))) == 0
    (run_dir,) = (tmp_path / "runs").glob("newcomer46*")
    assert run_dir.name == "newcomer46-ns46-Line-v0__ppo__s1" and checkpoints.checkpoints_of(run_dir)
    assert "| newcomer46:ns46/Line-v0 |" in (tmp_path / "results" / "table_discrete.md").read_text()


# --- issue 51: round four ------------------------------------------------------------------------------


def tiny_run(tmp_path, **overrides) -> Path:
    from conftest import small_args, train

    return train(ppo_pgg_discrete, small_args("discrete", tmp_path, **overrides))


def test_a_checkpoint_copied_elsewhere_keeps_its_own_runs_name(tmp_path):
    run_dir = tiny_run(tmp_path / "runs", run_name="nc4", total_timesteps=512)
    moved = tmp_path / "elsewhere" / "moved" / "mycartpole.pt"
    moved.parent.mkdir(parents=True)
    shutil.copy(checkpoints.checkpoint_path(run_dir, 512), moved)
    sweep.sweep(sweep.Args(paths=(str(moved),), output=str(tmp_path / "sweep"), gammas=(1.0,), episodes=1))
    assert {row["run"] for row in files.read_csv(tmp_path / "sweep" / "episodes.csv")} == {"nc4"}
    assert {row["run"] for row in files.read_csv(tmp_path / "sweep" / "evaluated_by.csv")} == {"nc4"}


def test_new_checkpoints_record_no_folder_of_the_machine_that_trained_them(tmp_path):
    run_dir = tiny_run(tmp_path.resolve() / "out", total_timesteps=512)
    ckpt = torch.load(checkpoints.checkpoint_path(run_dir, 512), weights_only=True)
    assert ckpt["args"]["output_dir"] == ".." and ckpt["run"] == run_dir.name  # relative to the run directory
    metadata = {key: value for key, value in ckpt.items() if key not in ("model", "resume")}
    assert str(tmp_path.resolve()) not in repr(metadata)
    assert str(tmp_path.resolve()) not in (run_dir / "args.json").read_text()


@pytest.mark.parametrize(
    "make,what",
    [
        (lambda p: p.mkdir() or p, "is a folder"),
        (lambda p: p / "missing.py", "no such file"),
        (lambda p: (p.write_text("x"), p)[1], "is not a Python file (.py)"),
    ],
)
def test_a_script_path_that_is_not_a_python_file_is_named_for_what_it_is(make, what, tmp_path):
    given = make(tmp_path / "fork")
    for module, flags in (
        (sweep, [str(FORMAT_2), "--output", str(tmp_path / "sweep")]),
        (bc_null, [str(FORMAT_2), "--output", str(tmp_path / "bc")]),
    ):
        line = one_line_error(run_main(module, *flags, "--script", str(given), cwd=ROOT))
        assert f"--script {given}" in line and what in line, line
    assert not (tmp_path / "sweep").exists() and not (tmp_path / "bc").exists()


def bc_null_cli(*flags) -> subprocess.CompletedProcess:
    """`python -m pgg_utils.bc_null *flags`, its main in this process (conftest.run_main)."""
    return run_main(bc_null, *flags, cwd=ROOT)


def test_bc_null_exits_2_with_the_reason_where_it_would_write_nothing(tmp_path):
    assert "no run directories, roots or checkpoint files given" in one_line_error(bc_null_cli())
    assert "--episode-seed must be a non-negative integer" in one_line_error(
        bc_null_cli(str(FORMAT_2), "--episode-seed", "-5", "--output", str(tmp_path / "bc"))
    )
    forked = torch.load(FORMAT_2, weights_only=True) | {"script_path": "/nowhere/ppo_fork.py"}
    path = tmp_path / "forked" / "checkpoints" / FORMAT_2.name
    path.parent.mkdir(parents=True)
    path.write_bytes(checkpoints.checkpoint_bytes(forked))
    line = one_line_error(bc_null_cli(str(path), "--output", str(tmp_path / "bc"), "--episodes", "1"))
    assert str(path) in line and "--script" in line
    assert not (tmp_path / "bc").exists()


@pytest.mark.parametrize(
    "flag,answer",
    [
        ("--gamma=0.9", "--discount"),
        ("--cuda", "CPU only"),
        ("--batch-size", "--num-envs × --num-steps"),
        ("--minibatch_size", "--num-minibatches"),
        ("--no-save-model", "always saved"),
    ],
)
def test_cleanrls_habitual_flags_are_answered_in_one_line(flag, answer, tmp_path):
    line = one_line_error(run_main(ppo_pgg_discrete, flag, "--output-dir", str(tmp_path)))
    assert answer in line and line.startswith(f"error: {flag.split('=')[0]}")
    assert not any(tmp_path.iterdir())


def test_cleanrls_flags_whose_meaning_holds_are_accepted_with_a_note():
    proc = run_main(ppo_pgg_continuous, "--no_cuda", "--save-model", "--help")
    assert proc.returncode == 0 and "--discount" in proc.stdout
    assert "note: --no_cuda: these scripts train on the CPU only" in proc.stderr and "note: --save-model" in proc.stderr


class LegacyRandomTask(gym.Env):
    """A task whose RNG is a legacy RandomState, as dm_control's through shimmy."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, render_mode=None):
        self.render_mode, self.random_state = render_mode, np.random.RandomState(0)

    @property
    def np_random(self):
        return self.random_state

    def observe(self):
        return self.random_state.uniform(-1, 1, 3).astype(np.float32)

    def reset(self, seed=None, options=None):
        if seed is not None:
            self.random_state = np.random.RandomState(seed)
        return self.observe(), {}

    def step(self, action):
        return self.observe(), float(action), False, False, {}


@pytest.mark.slow
def test_a_task_whose_rng_is_a_legacy_random_state_is_saved_and_restored(tmp_path):
    gym.register("LegacyRandomTask-v0", entry_point=LegacyRandomTask, max_episode_steps=20)
    run_dir = tiny_run(tmp_path, env_id="LegacyRandomTask-v0", run_name="legacy")
    ckpt = torch.load(checkpoints.checkpoint_path(run_dir, 512), weights_only=True)
    (saved,) = {env["rng"]["random_state"]["bit_generator"] for env in ckpt["resume"]["envs"]}
    assert saved == "MT19937"
    from pgg_utils import training_state

    task = LegacyRandomTask()
    training_state.set_generator_state(task.np_random, ckpt["resume"]["envs"][0]["rng"])
    again = LegacyRandomTask()
    training_state.set_generator_state(again.np_random, training_state.generator_state(task.np_random))
    assert np.array_equal(task.observe(), again.observe())
    checkpoints.checkpoint_path(run_dir, 1536).unlink()
    from conftest import small_args, train

    train(
        ppo_pgg_discrete, small_args("discrete", tmp_path, env_id="LegacyRandomTask-v0", run_name="legacy", resume=True)
    )
    assert checkpoints.checkpoint_path(run_dir, 1536).exists()


@pytest.mark.slow
def test_shipped_agents_name_no_folder_of_the_machine_that_trained_them():
    """Every committed agent records its output folder relative to its run and its run's name
    (benchmarks/relocate_agents.py rewrote those two fields, every tensor unchanged); before, each held
    the training machine's absolute output folder."""
    from pgg_utils.checkpoints import read_checkpoint_file

    paths = sorted((ROOT / "results").rglob("checkpoints/step_*.pt"))
    assert len(paths) > 1000
    for path in paths:
        ckpt = read_checkpoint_file(path)
        assert (ckpt["args"]["output_dir"], ckpt["run"]) == ("..", path.parent.parent.name), path
