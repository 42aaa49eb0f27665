import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT, one_line_error, run_main

import reproduce
from beyond import sets as beyond_sets
from paper_study import agents, paper
from pgg_utils import checkpoints
from pgg_utils.files import RECORD, InputError, lock_directory, read_csv, sha256_of

TINY = ["--total-timesteps", "2048", "--checkpoint-interval", "1024", "--seeds", "2", "--variants", "ppo", "pgg_g1.1",
        "--gammas", "1", "2", "--episodes", "3"]  # fmt: skip


# The ids of today's grid (paper.VARIANTS, then paper.BEYOND_VARIANTS): what its runs, tables and committed outputs
# are named by.
GRID_VARIANTS = ("ppo", "pgg_g1.1", "pgg_drop0.1", "pgg_g1to1.2", "pgg_adaptive1.1_kl0.04", "pgg_g1.1_goal",
                 "pgg_g1.1_bc0.1", "pgg_g1.1_null17", "pgg_drop0.1_goal", "pgg_drop0.1_null17")  # fmt: skip


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


@pytest.mark.slow
def test_quick_preset_runs_end_to_end_locally(local_results):
    table = (local_results / "table_discrete.md").read_text()
    assert "| Method | CartPole-v1 |" in table and "| PPO |" in table and "| pgg_g1.1 |" in table
    episodes = (local_results / "episodes.csv").read_text().splitlines()
    assert len(episodes) - 1 == 2 * 2 * 2 * 2 * 3  # seeds × variants × checkpoints × γ × episodes
    for name in ("fig_discrete_pgg_g1.1.png", "learning_curves.png", "compare_paper.md", "table_discrete.tex"):
        assert (local_results / name).exists(), name


@pytest.mark.slow
def test_the_agents_are_exported_without_resume_state_and_sweep_to_the_same_episodes(local_results, tmp_path):
    import torch

    import eval_gamma_sweep

    agents = local_results / "agents"
    files = sorted(agents.rglob("step_*.pt"))
    assert len(files) == 2 * 2 * 2  # seeds × variants × checkpoints
    readme = (agents / "README.md").read_text()
    assert "| CartPole-v1__pgg_g1.1__s2 | CartPole-v1 | pgg_g1.1 | 2 | 1,024, 2,048 |" in readme
    agent = torch.load(files[0], weights_only=True)
    assert "resume" not in agent and agent["model"] and agent["code"]["sha1"]
    assert files[0].stat().st_size < 60_000
    swept = eval_gamma_sweep.sweep(eval_gamma_sweep.Args(paths=(str(agents),), output=str(tmp_path / "sweep"),
                                                         gammas=(1.0, 2.0), episodes=3))  # fmt: skip
    assert (swept / "episodes.csv").read_text() == (local_results / "episodes.csv").read_text()


@pytest.mark.slow
def test_a_one_seed_grid_after_a_two_seed_grid_leaves_only_its_own_agents(local_results, tmp_path):
    """`reproduce.py --preset quick --seeds 1` after the 2-seed preset left the seed-2 agents and their
    README rows beside the 1-seed tables: the agents folder holds the agents of the tables beside it, so
    an export removes those an earlier export wrote and it does not (their emptied folders too), and no
    file of the user's."""
    import shutil

    two_seeds = reproduce.grid(tiny_args(local_results.parent.parent, "local"))
    one_seed = [s for s in two_seeds if s.seed == 1]
    folder = tmp_path / "agents"
    shutil.copytree(local_results / "agents", folder)  # the 2-seed grid's export
    (folder / two_seeds[-1].name / "notes.md").write_text("the user's")
    agents.export_agents(one_seed, folder)
    readme = (folder / "README.md").read_text()
    listed = [line.split(" | ")[0].removeprefix("| ") for line in readme.splitlines()[10:] if line.startswith("| ")]
    assert sorted(listed) == sorted(s.name for s in one_seed) and readme.count("| run | env |") == 1
    assert sorted(p.relative_to(folder).parts[0] for p in folder.rglob("step_*.pt")) == sorted(
        s.name for s in one_seed for _ in checkpoints.checkpoints_of(s.run_dir))  # fmt: skip
    dirs = {p.name for p in folder.iterdir() if p.is_dir()}
    assert dirs == {s.name for s in one_seed} | {two_seeds[-1].name}  # kept for the user's file alone
    assert [p.name for p in (folder / two_seeds[-1].name).iterdir()] == ["notes.md"]


@pytest.mark.slow
def test_quick_preset_through_submitit_local_executor(local_results, tmp_path):
    """One run of the local grid (seed 1 of PPO), trained and swept through submitit's local executor, gives the
    local launcher's episodes of that run, row for row."""
    args = tiny_args(tmp_path, "submitit", executor="submitit-local", seeds=1, variants=("ppo",))
    assert reproduce.reproduce(args) == 0
    results = tmp_path / "submitit" / "results"
    submitted, local = read_csv(results / "episodes.csv"), read_csv(local_results / "episodes.csv")
    assert len(submitted) == 2 * 2 * 3  # checkpoints × γ × episodes
    assert submitted == [row for row in local if row["run"] == "CartPole-v1__ppo__s1"]
    assert (results / "table_discrete.md").exists()


def processes_mentioning(text: str) -> list[int]:
    """PIDs of live processes whose command line contains `text`."""
    found = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                if text.encode() in f.read():
                    found.append(int(entry))
        except (OSError, ValueError):
            continue
    return found


@pytest.mark.slow
@pytest.mark.skipif(
    sys.platform != "linux", reason="children die with a SIGKILLed launcher through Linux's PR_SET_PDEATHSIG"
)
def test_launcher_killed_mid_grid_leaves_no_orphan_and_its_rerun_equals_an_uninterrupted_grid(tmp_path):
    """Fault injection: SIGKILL to the launcher alone while a run is between checkpoints. Its training
    child dies with it; the rerun resumes that run from its last checkpoint (bit for bit) and skips the
    finished ones, and the final CSVs equal those of a grid that was never interrupted."""
    grid = ["--total-timesteps", "8192", "--checkpoint-interval", "2048", "--seeds", "1", "--variants", "ppo",
            "pgg_g1.1", "--gammas", "1", "2", "--episodes", "3", "--workers", "1"]  # fmt: skip

    def command(name: str) -> list[str]:
        return [sys.executable, str(ROOT / "reproduce.py"), *grid, "--root", str(tmp_path / name / "runs"),
                "--results", str(tmp_path / name / "results")]  # fmt: skip

    reference = subprocess.run(
        command("straight"), capture_output=True, text=True, cwd=tmp_path, timeout=600, check=False
    )
    assert reference.returncode == 0, reference.stderr[-2000:]

    root = tmp_path / "killed" / "runs"
    launcher = subprocess.Popen(command("killed"), stderr=subprocess.DEVNULL, cwd=tmp_path)
    first_of_second_run = root / "CartPole-v1__pgg_g1.1__s1" / "checkpoints" / "step_000002048.pt"
    deadline = time.time() + 300
    while not first_of_second_run.exists() and time.time() < deadline:
        time.sleep(0.02)
    launcher.kill()
    launcher.wait()
    assert not (root / "CartPole-v1__pgg_g1.1__s1" / "checkpoints" / "step_000008192.pt").exists(), "killed too late"
    deadline = time.time() + 10
    while processes_mentioning(str(root)) and time.time() < deadline:
        time.sleep(0.1)
    assert processes_mentioning(str(root)) == [], "a training child outlived the launcher"

    rerun = subprocess.run(command("killed"), capture_output=True, text=True, cwd=tmp_path, timeout=600, check=False)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    assert "2 runs in the grid: 1 trained, 1 half done (CartPole-v1__pgg_g1.1__s1 at step " in rerun.stderr
    assert "resuming from" in (root / "logs" / "CartPole-v1__pgg_g1.1__s1.log").read_text()
    for name in ("episodes.csv", "summary.csv"):
        straight = (tmp_path / "straight" / "results" / name).read_text()
        assert (tmp_path / "killed" / "results" / name).read_text() == straight.replace("straight", "killed")


@pytest.mark.slow
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


@pytest.mark.slow
def test_sweeping_an_unfinished_run_is_said_with_its_last_step_and_its_trainer(tmp_path, capsys):
    args = tiny_args(tmp_path, "partial", variants=("ppo",))
    assert reproduce.reproduce(args) == 0
    run = tmp_path / "partial" / "runs" / "CartPole-v1__ppo__s2"
    (run / "checkpoints" / "step_000002048.pt").unlink()
    capsys.readouterr()
    lock = lock_directory(run)  # as a trainer still at work on it would hold it
    try:
        assert reproduce.reproduce(replace(args, skip_training=True)) == 0
    finally:
        lock.close()
    err = capsys.readouterr().err
    assert (f"note: unfinished, so swept up to the last checkpoint: CartPole-v1__ppo__s2 (1,024, being trained now "
            f"by pid {os.getpid()})") in err  # fmt: skip
    assert reproduce.reproduce(replace(args, skip_training=True)) == 0  # its trainer gone, the lock free
    assert "CartPole-v1__ppo__s2 (1,024)" in capsys.readouterr().err
    episodes = (tmp_path / "partial" / "results" / "episodes.csv").read_text().splitlines()
    assert len(episodes) - 1 == (2 + 1) * 2 * 3  # s1: two checkpoints, s2: one; × γ × episodes


@pytest.mark.slow
def test_submitit_local_executor_works_when_launched_as_a_command(tmp_path):
    """The jobs unpickle reproduce.TrainingTask, not __main__'s, and import it from anywhere: the command
    runs from a directory that does not hold reproduce.py."""
    command = [sys.executable, str(ROOT / "reproduce.py"), "--executor", "submitit-local", "--envs", "CartPole-v1",
               "--seeds", "1", "--variants", "ppo", "--total-timesteps", "1024", "--checkpoint-interval", "512",
               "--episodes", "2", "--gammas", "1", "2", "--root", str(tmp_path / "grid"),
               "--results", str(tmp_path / "results")]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "grid" / "CartPole-v1__ppo__s1" / "checkpoints" / "step_000001024.pt").exists()
    assert len((tmp_path / "results" / "episodes.csv").read_text().splitlines()) - 1 == 2 * 2 * 2
    assert (tmp_path / "results" / "table_discrete.md").exists()


def children_of(pid: int) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat") as f:
                if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry))
        except (OSError, ValueError, IndexError):
            continue
    return found


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="finds the job's task process through /proc")
def test_preempted_submitit_job_is_requeued_and_resumes_from_its_last_checkpoint(tmp_path):
    """Slurm's preemption signal (SIGUSR2) to the job's task between checkpoints, as submitit's local
    controller sends it before a timeout: submitit calls TrainingTask.checkpoint, the job is requeued,
    and the requeued task resumes the run from its last checkpoint to the end."""
    import submitit

    spec = reproduce.RunSpec("CartPole-v1", "ppo", 1, str(tmp_path / "runs"), 16384, 2048)
    executor = submitit.LocalExecutor(folder=tmp_path / "submitit")
    executor.update_parameters(timeout_min=60)  # far from it: a preemption, not a timeout
    with reproduce.importable_by_jobs():
        job = executor.submit(reproduce.TrainingTask(), spec)
    first = checkpoints.checkpoint_path(spec.run_dir, 2048)
    deadline = time.time() + 300
    while not first.exists() and time.time() < deadline:
        time.sleep(0.02)
    (task,) = children_of(job._process.pid)
    assert not spec.final_checkpoint.exists(), "preempted too late"
    os.kill(task, signal.SIGUSR2)
    deadline = time.time() + 300
    while not job.done() and time.time() < deadline:
        time.sleep(0.1)
    job.result()
    assert "this job is preempted" in job.stdout() and "Requeued job" in job.stdout()
    log = spec.log.read_text()
    assert f"resuming from {spec.run_dir}/checkpoints/step_" in log
    assert spec.final_checkpoint.exists()
    assert processes_mentioning(str(spec.run_dir)) == [], "the preempted task's training child outlived it"


@pytest.mark.slow
def test_a_job_that_fails_before_its_log_exists_is_reported_with_submitits_log(tmp_path, capsys):
    root = tmp_path / "failing" / "runs"
    root.mkdir(parents=True)
    (root / "logs").write_text("")  # a file where the logs' directory goes: train_one fails before any log
    args = tiny_args(tmp_path, "failing", executor="submitit-local", seeds=1, variants=("ppo",))
    with pytest.raises(reproduce.InputError, match="no run has any checkpoint to sweep"):
        reproduce.reproduce(args)
    (failed,) = [line for line in capsys.readouterr().err.splitlines() if line.startswith("FAILED")]
    assert failed.startswith("FAILED CartPole-v1__ppo__s1: ") and "; log: " in failed
    log = failed.split("; log: ")[-1]
    assert log.startswith(str(root / "submitit")) and log.endswith(".err") and "Error" in Path(log).read_text()


def test_the_launch_counts_trained_half_done_and_not_started_runs(tmp_path):
    specs = reproduce.grid(tiny_args(tmp_path, "state", variants=("ppo",), seeds=3))
    for spec, steps in zip(specs, ((1024, 2048), (1024,), ()), strict=True):
        for step in steps:
            checkpoints.checkpoint_path(spec.run_dir, step).parent.mkdir(parents=True, exist_ok=True)
            checkpoints.checkpoint_path(spec.run_dir, step).touch()
    assert reproduce.grid_state(specs) == (
        "3 runs in the grid: 1 trained, 1 half done (CartPole-v1__ppo__s2 at step 1,024), 1 not started"
    )


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--envs", "CartPol-v1"], "error: --envs: cannot make environment 'CartPol-v1'"),
        (["--seeds", "-1"], "error: --seeds must be positive, got -1"),
        (["--seeds", "0"], "error: --seeds must be positive, got 0"),
        (["--workers", "0"], "error: --workers must be positive, got 0"),
        (["--total-timesteps", "0"], "error: --total-timesteps must be positive, got 0"),
        (["--episodes", "0"], "error: --episodes must be positive, got 0"),
        (["--checkpoint-interval", "0"], "error: --checkpoint-interval must be positive, got 0"),
        (["--checkpoint-interval", "256"], "error: --checkpoint-interval must be at least one batch"),
        (["--gammas", "1", "nan"], "error: --gammas must be a number in [0, 1000], got nan"),
        (["--variants", "ppo", "ppo"], "error: --variants lists a value twice"),
        (["--variants", "pgg_g1.1_goal"], "error: --variants: pgg_g1.1_goal needs goal dimensions; only Reacher-v4, "),
        (["--variants", "pgg_g1.1_null17"], "error: --variants: pgg_g1.1_null17 has flags that ppo_pgg_discrete.py"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2_before_anything_is_created(tmp_path, flags, message):
    done = run_main(reproduce, *flags, "--root", tmp_path / "runs", "--results", tmp_path / "results", cwd=tmp_path)
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1, done.stderr
    assert done.stderr.startswith(message), done.stderr
    assert sorted(os.listdir(tmp_path)) == []


@pytest.mark.slow
def test_the_results_hold_the_sweeps_record_and_the_tables_refuse_a_cut_copy(local_results, tmp_path):
    """The sweep's written.csv travels with its episodes.csv into the results; plot_results.py checks the
    file against it, so that a copy cut at any line is refused, not tabled as whole."""
    import plot_results

    record = {r["file"]: r for r in read_csv(local_results / RECORD)}
    assert record["episodes.csv"]["rows"] == str(2 * 2 * 2 * 2 * 3)
    assert record["episodes.csv"]["sha256"] == sha256_of(local_results / "episodes.csv")
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / RECORD).write_bytes((local_results / RECORD).read_bytes())
    lines = (local_results / "episodes.csv").read_text().splitlines(keepends=True)
    (copy / "episodes.csv").write_text("".join(lines[: 1 + 3 * 2]))  # two whole cells of the first run
    with pytest.raises(InputError, match="is not the file its eval_gamma_sweep.py wrote: it holds 6 rows"):
        plot_results.generate(plot_results.Args(sweeps=(str(copy),), output=str(tmp_path / "tables")))


def test_a_second_launcher_into_the_same_results_is_refused_before_training(tmp_path):
    """Two launchers with different --root and one --results would leave one grid's tables beside the
    agents of both: the second is refused in one line, before it trains anything."""
    args = tiny_args(tmp_path, "second", seeds=1, variants=("ppo",))
    Path(args.results).mkdir(parents=True)
    lock = lock_directory(Path(args.results), "a test")  # as a first launcher (or plot_results.py) holds it
    try:
        with pytest.raises(InputError, match=f"{args.results} is in use by .* choose another --results"):
            reproduce.reproduce(args)
    finally:
        lock.close()
    assert not any(Path(args.root).glob("CartPole-v1__*")), "the refused launcher trained"


@pytest.mark.slow
def test_help_ends_the_variant_list_before_the_next_sentence():
    done = subprocess.run([sys.executable, str(ROOT / "reproduce.py"), "--help"], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "COLUMNS": "200"}, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert any(
        line.strip() == "pgg_drop0.1  PGG, γ_train = 1, conditioning dropout 0.1" for line in done.stdout.splitlines()
    )
    assert "dropout 0.1 Run directories" not in done.stdout


def test_the_grids_variants_are_named_by_variant_id_and_keep_todays_ids():
    """paper.py writes a variant as its training flags alone; reproduce names it by identity.variant_id of those flags
    as the training script parses them. The ids of today's grid stay, the same on every task it runs on, and the
    readers' literal ids (the paper's order, its tables' rows, beyond_report's families) are the derived ones."""
    named = reproduce.grid_variants()
    assert tuple(named) == reproduce.VARIANT_IDS == GRID_VARIANTS
    assert reproduce.PAPER_VARIANT_IDS == paper.PAPER_ORDER == GRID_VARIANTS[: len(paper.VARIANTS)]
    assert all(preset.variants == paper.PAPER_ORDER for preset in reproduce.PRESETS.values())
    assert [paper.variant_rank(v) for v in GRID_VARIANTS] == [0, 1, 2, 3, 3, 3, 3, 3, 3, 3]
    for variant, flags in named.items():
        for env_id in ("Pusher-v4", "Reacher-v4") if "{goal}" in flags else ("Hopper-v4", "Pusher-v4", "Reacher-v4"):
            assert reproduce.variant_name(flags, env_id, "continuous") == variant
    assert [reproduce.variant_name(named[v], "CartPole-v1", "discrete") for v in GRID_VARIANTS[:5]] == [
        *GRID_VARIANTS[:5]
    ]

    def family(flag: str) -> set[str]:
        return {variant for variant, flags in named.items() if flag in flags}

    assert beyond_sets.CLONING_VARIANTS == family("--null-bc-coef")
    assert beyond_sets.GOAL_VARIANTS == family("{goal}") - family("--cond-dropout")
    assert set(beyond_sets.DROPOUT_VARIANTS) == family("--null-dims") & family("--cond-dropout")
    assert beyond_sets.SCHEDULE_VARIANTS == family("--guidance-schedule")
    assert beyond_sets.BEYOND_VARIANT_IDS == set(GRID_VARIANTS[len(paper.VARIANTS) :])
    assert set(beyond_sets.COMMAND_VARIANTS) <= set(GRID_VARIANTS)
    assert {v for v in GRID_VARIANTS if paper.paper_rows(v) is not None} == {"ppo", "pgg_g1.1"}
    # the other readers' literal ids, which would otherwise drop a comparison or a colour without a word
    import plot_results
    from paper_study import figures
    from paper_study.data import read_dropout_figure

    assert set(beyond_sets.BASELINES) <= set(paper.PAPER_ORDER) == set(figures.VARIANT_COLOURS)
    assert {variant for _, variant in plot_results.PAPER_FIGURE_GAMMAS} <= set(paper.PAPER_ORDER)
    assert {variant for variant, _ in read_dropout_figure.LINE_COLOURS} <= set(paper.PAPER_ORDER)


def test_the_committed_agents_were_trained_by_the_commands_the_grid_gives_today():
    """Every run of every committed agents README (all eight variants) is named, and trained by a command, exactly
    as reproduce's grid names and launches that env, variant and seed now."""
    readmes = sorted((ROOT / "results").rglob("agents/README.md"))
    rows = [line.split(" | ") for readme in readmes for line in readme.read_text().splitlines()
            if line.startswith("| ") and "`python " in line]  # fmt: skip
    assert {row[2] for row in rows} == set(GRID_VARIANTS)
    for row in rows:
        name, env_id, variant, seed, command = row[0].removeprefix("| "), row[1], row[2], int(row[3]), row[5]
        words = command.strip("` |").split()
        optional = {flag: int(words[words.index(flag) + 1]) if flag in words else None
                    for flag in ("--total-timesteps", "--checkpoint-interval")}  # fmt: skip
        spec = reproduce.RunSpec(env_id, variant, seed, words[words.index("--output-dir") + 1],
                                 *optional.values(), "--compile" in words)  # fmt: skip
        assert spec.name == name
        assert ["python", Path(spec.command()[1]).name, *spec.command()[2:]] == words


@pytest.mark.slow
def test_a_variant_added_to_paper_py_as_flags_alone_is_launched_under_its_variant_id(tmp_path):
    """A variant written into paper.BEYOND_VARIANTS as its flags, with no id anywhere, is a choice of --variants
    under the id identity.variant_id gives a run of those flags, and the grid names and trains its runs so."""
    code = (
        "import tyro\n"
        "from paper_study import paper\n"
        "paper.BEYOND_VARIANTS += (('--guidance', '1.2', '--cond-dropout', '0.05', '--null-bc-coef', '0.2'),)\n"
        "import reproduce\n"
        "args = tyro.cli(reproduce.Args, args=['--envs', 'CartPole-v1', '--seeds', '1', '--variants', "
        "'pgg_g1.2_drop0.05_bc0.2', 'ppo', '--root', 'runs'])\n"
        "assert reproduce.argument_error(args) is None, reproduce.argument_error(args)\n"
        "print('\\n'.join(' '.join(spec.command()[2:]) for spec in reproduce.grid(args)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    flags_of_run = {"CartPole-v1__pgg_g1.2_drop0.05_bc0.2__s1": "--guidance 1.2 --cond-dropout 0.05 --null-bc-coef 0.2",
                    "CartPole-v1__ppo__s1": "--guidance 1.0 --cond-dropout 0.0"}  # fmt: skip
    assert done.stdout.splitlines() == [
        f"--env-id CartPole-v1 --seed 1 {flags} --output-dir runs --run-name {name} --torch-threads 1 "
        "--total-timesteps 50000 --checkpoint-interval 25000"  # the quick preset's
        for name, flags in flags_of_run.items()
    ]


def test_a_variant_that_its_flags_name_otherwise_on_a_task_is_refused_there(monkeypatch, tmp_path):
    """A variant is named on one task (reproduce.NAMING_ENV); where its flags give its runs another id (the null on
    20 21 22 is Pusher-v4's goal), the grid refuses it in one line rather than name runs for the wrong variant."""
    nulled = ("--guidance", "1.1", "--null-dims", "20", "21", "22")
    monkeypatch.setattr(paper, "BEYOND_VARIANTS", (*paper.BEYOND_VARIANTS, nulled))
    reproduce.grid_variants.cache_clear()
    try:
        assert reproduce.grid_variants()["pgg_g1.1_null20-21-22"] == nulled
        args = tiny_args(tmp_path, "nulled", envs=("Pusher-v4",), variants=("pgg_g1.1_null20-21-22",))
        assert reproduce.argument_error(args) == (
            "--variants: pgg_g1.1_null20-21-22's flags give its runs on Pusher-v4 the variant id pgg_g1.1_goal"
        )
    finally:
        reproduce.grid_variants.cache_clear()  # named again from paper.py's own variants


@pytest.mark.slow
def test_a_grid_variant_that_differs_from_another_by_any_flag_gets_an_id_of_its_own(tmp_path):
    """A variant that its variant id alone would confuse with the paper's PGG (it adds --learning-rate) is named by
    the id and the argument its flags set otherwise, and the grid launches it so; a variant that trains the same runs
    as another is one line of error, exit 2. Today's main stopped every reproduce.py command at import with a
    ValueError traceback ("... are both pgg_g1.1")."""
    added = "paper.BEYOND_VARIANTS += (('--guidance', '1.1', '--learning-rate', '0.001'),)\n"
    code = (
        "import tyro\n"
        "from paper_study import paper\n"
        f"{added}"
        "import reproduce\n"
        "args = tyro.cli(reproduce.Args, args=['--envs', 'CartPole-v1', '--seeds', '1', '--variants', "
        "'pgg_g1.1_learning_rate0.001', 'pgg_g1.1', '--root', 'runs'])\n"
        "assert reproduce.argument_error(args) is None, reproduce.argument_error(args)\n"
        "print('\\n'.join(' '.join(spec.command()[2:]) for spec in reproduce.grid(args)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    flags_of_run = {"CartPole-v1__pgg_g1.1_learning_rate0.001__s1": "--guidance 1.1 --learning-rate 0.001",
                    "CartPole-v1__pgg_g1.1__s1": "--guidance 1.1 --cond-dropout 0.0"}  # fmt: skip
    assert done.stdout.splitlines() == [
        f"--env-id CartPole-v1 --seed 1 {flags} --output-dir runs --run-name {name} --torch-threads 1 "
        "--total-timesteps 50000 --checkpoint-interval 25000"
        for name, flags in flags_of_run.items()
    ]
    same = "paper.BEYOND_VARIANTS += (('--guidance', '1.1', '--cond-dropout', '0'),)\n"
    done = subprocess.run([sys.executable, "-c", f"from paper_study import paper\n{same}import reproduce\n"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert one_line_error(done) == ("error: paper.py's variants --guidance 1.1 --cond-dropout 0.0 and --guidance 1.1 "
                                    "--cond-dropout 0 train the same runs (pgg_g1.1): remove one")  # fmt: skip
