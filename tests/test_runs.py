"""Run directories and checkpoints of both training scripts: resume, refusal to overwrite, the lock,
one-line errors, Ctrl-C, progress, videos, and the PPO statistics under conditioning dropout."""

import json
import os
import pty
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import (
    ROOT,
    SCRIPTS,
    default_sigint,
    one_line_error,
    run_main,
    run_script,
    small_args,
    train,
    training_vector_env,
)

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import checkpoints, checks, files, identity, progress, runs, scripts, training_state
from pgg_utils.files import lock_directory


def checkpoint(run_dir, mark) -> dict:
    return torch.load(checkpoints.checkpoint_path(run_dir, mark), weights_only=True)


def run_training(kind: str, *flags, **kwargs):
    return run_script(f"{SCRIPTS[kind].__name__}.py", *flags, **kwargs)


def run_here(kind: str, *flags):
    """run_training without a new Python (conftest.run_main): the argument and run-directory errors."""
    return run_main(SCRIPTS[kind], *flags)


def default_run_name(args, script: Path = ROOT / "ppo_pgg_discrete.py") -> str:
    """The run directory name a training script gives `args` without --run-name."""
    return identity.Configuration.of_run(script, "discrete", args).run_name


def prepare(module, args) -> None:
    """Applies the run directory's rules as the script's main does before it trains (RunDirError)."""
    runs.Run.prepare(args, module.ACTION_SPACE, Path(module.__file__)).close()


# --- resume ------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_resumed_run_is_bit_identical_to_an_uninterrupted_one(kind, tmp_path):
    """Stopped after its first checkpoint (mid-episode) and resumed, a run ends with the same weights,
    optimizer state and normalisation statistics as the run that was never stopped: the checkpoint
    holds everything the next iteration reads. Same machine and code: equal bits by construction."""
    module = SCRIPTS[kind]
    args = small_args(kind, tmp_path, run_name="straight")
    straight = train(module, args)
    first, last = args.checkpoint_interval, args.total_timesteps
    stopped = tmp_path / "stopped"
    shutil.copytree(straight, stopped)
    for later in checkpoints.checkpoint_path(stopped, first).parent.glob("*.pt"):
        if later.name > checkpoints.checkpoint_path(stopped, first).name:
            later.unlink()
    resumed = train(module, replace(args, run_name="stopped", resume=True))
    a, b = checkpoint(straight, last), checkpoint(resumed, last)
    assert a["model"].keys() == b["model"].keys()
    assert all(torch.equal(a["model"][key], b["model"][key]) for key in a["model"])
    assert torch.equal(a["resume"]["optimizer"]["state"][0]["exp_avg"], b["resume"]["optimizer"]["state"][0]["exp_avg"])
    assert a["resume"]["iteration"] == b["resume"]["iteration"] and a["global_step"] == b["global_step"]


def test_resume_continues_the_learning_rate_schedule_and_purges_later_events(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    args = small_args("discrete", tmp_path, cond_dropout=0.0)
    run_dir = train(ppo_pgg_discrete, args)
    checkpoints.checkpoint_path(run_dir, 1536).unlink()  # as if stopped after the 1024 checkpoint
    train(ppo_pgg_discrete, replace(args, resume=True))
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    rates = events.Scalars("charts/learning_rate")
    steps = [event.step for event in rates]
    assert steps == list(range(256, 1537, 256)), "each iteration (4 envs x 64 steps) logged once"
    expected = [(1 - i / 6) * args.learning_rate for i in range(6)]
    np.testing.assert_allclose([event.value for event in rates], expected, rtol=1e-6)


def test_format_one_checkpoints_load_for_evaluation_but_do_not_resume(tmp_path):
    args = small_args("discrete", tmp_path, total_timesteps=1024)
    run_dir = train(ppo_pgg_discrete, args)
    path = checkpoints.checkpoint_path(run_dir, 512)
    old = checkpoint(run_dir, 512)
    old = {key: value for key, value in old.items() if key not in ("resume", "versions")} | {"format_version": 1}
    torch.save(old, path)
    checkpoints.checkpoint_path(run_dir, 1024).unlink()
    agent, ckpt = ppo_pgg_discrete.load_checkpoint(path)
    assert ckpt["format_version"] == 1 and torch.equal(agent.null_obs, old["model"]["null_obs"])
    with pytest.raises(runs.RunDirError, match="predates resumable checkpoints"):
        prepare(ppo_pgg_discrete, replace(args, resume=True))
    assert path.exists()


def test_one_checkpoint_per_saved_iteration():
    """A mark that the last iteration passes is left to the total's checkpoint: interval 3900 of a
    4000-step run of 512-step batches would otherwise write step_3900 and step_4000 at one point."""
    assert checkpoints.checkpoint_marks(4000, 3900, 512) == [4000]
    assert checkpoints.checkpoint_marks(2500, 1024, 256) == [1024, 2048, 2500]


def test_a_full_disk_while_saving_is_one_line_naming_the_file_and_leaves_the_previous_ones_whole(
    tmp_path, monkeypatch, capsys
):
    """A checkpoint is written to a temporary file and renamed: a write that dies half way (full disk)
    leaves no step_*.pt and no .tmp behind, the earlier checkpoints as they were, and one line of error
    that names the file."""
    args = small_args("discrete", tmp_path)
    real_open = open

    def full_at_the_second(path, mode="r", *rest, **kwargs):
        handle = real_open(path, mode, *rest, **kwargs)
        if "step_000001024" in str(path) and "w" in mode:
            handle.write(b"half a checkpoint")
            handle.close()
            raise OSError(28, "No space left on device")
        return handle

    monkeypatch.setattr(files, "open", full_at_the_second, raising=False)
    with pytest.raises(SystemExit) as exit_status:
        runs.launch(args, "discrete", ppo_pgg_discrete.__file__, ppo_pgg_discrete.train)
    error = capsys.readouterr().err.strip().splitlines()
    assert exit_status.value.code == 1 and len(error) == 1, error
    assert (
        "step_000001024.pt" in error[0]
        and "No space left on device" in error[0]
        and "step_000000512.pt are kept" in error[0]
    )
    run_dir = tmp_path / default_run_name(args)
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["step_000000512.pt"]
    ppo_pgg_discrete.load_checkpoint(run_dir / "checkpoints" / "step_000000512.pt")


class Drift(gym.Env):
    """A task whose state is private (no `state`, no MuJoCo `data`): a checkpoint cannot hold it."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (1,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self._x = 0.0
        return np.array([self._x]), {}

    def step(self, action):
        self._x += float(action[0])
        return np.array([self._x]), 1.0 + self._x, False, False, {}


def test_env_state_without_task_state_keeps_the_wrapper_statistics(monkeypatch):
    """Such a task is marked incomplete (a resumed run starts fresh episodes), but its wrappers'
    statistics, here the reward scale, are still saved and restored."""
    monkeypatch.setattr(ppo_pgg_continuous, "make_env", lambda env_id, video_dir=None: Drift)
    envs = training_vector_env(ppo_pgg_continuous, "Drift", 1, seed=0)
    envs.reset(seed=0)
    for _ in range(5):
        envs.step(np.full((1, 1), 0.5, np.float32))
    states = training_state.env_state(envs)
    assert states[0]["complete"] is False
    fresh = training_vector_env(ppo_pgg_continuous, "Drift", 1, seed=0)
    fresh.reset(seed=1)
    training_state.restore_env_state(fresh, states)
    saved, restored = (next(w for w in training_state.wrapper_chain(e.envs[0]) if isinstance(w, ppo_pgg_continuous.NormalizeClipReward))
                       for e in (envs, fresh))  # fmt: skip
    assert restored.return_count == saved.return_count == 1e-4 + 5 and restored.return_var == saved.return_var


def test_checkpoint_records_the_software_stack_and_the_cpu(tmp_path):
    ckpt = checkpoint(train(ppo_pgg_discrete, small_args("discrete", tmp_path, total_timesteps=512)), 512)
    assert ckpt["versions"]["torch"] == torch.__version__ and ckpt["versions"]["gymnasium"]
    assert ckpt["machine"] == checkpoints.machine() and torch.backends.cpu.get_cpu_capability() in ckpt["machine"]
    # The training code: the script and the pgg_utils modules it ran, by commit and by content.
    assert (
        len(ckpt["code"]["sha1"]) == 40
        and ckpt["code"]["files"][0] == "ppo_pgg_discrete.py"
        and "runs.py" in ckpt["code"]["files"]
    )
    assert ckpt["code"]["commit"] is None or len(ckpt["code"]["commit"]) == 40


# --- a run directory is never destroyed or shared ------------------------------------------------


def test_rerun_with_other_arguments_is_refused_before_touching_the_run(tmp_path):
    args = small_args("discrete", tmp_path, total_timesteps=1024)
    run_dir = train(ppo_pgg_discrete, args)
    before = {path: path.read_bytes() for path in run_dir.rglob("*") if path.is_file() and path.name != ".lock"}
    proc = run_here(
        "discrete", "--output-dir", str(tmp_path), "--run-name", run_dir.name, "--total-timesteps", "1024",
        "--checkpoint-interval", "512", "--num-steps", "64", "--guidance", "1.1", "--cond-dropout", "0.1",
        "--learning-rate", "0.002",
    )  # fmt: skip
    line = one_line_error(proc)
    assert str(run_dir) in line and "learning_rate 0.00025 -> 0.002" in line and "--overwrite" in line
    assert {path: path.read_bytes() for path in before} == before


@pytest.mark.parametrize("flag", [["--learning-rate", "nan"], ["--guidance", "1e39"], ["--checkpoint-interval", "100"],
                                  ["--seed", "-1"], ["--seed", "18446744073709551617"]])  # fmt: skip
def test_invalid_arguments_are_refused_before_touching_the_disk(flag, tmp_path):
    line = one_line_error(run_here("discrete", "--output-dir", str(tmp_path / "runs"), *flag))
    assert flag[0] in line
    assert not (tmp_path / "runs").exists()


def test_finished_and_unfinished_runs_need_an_explicit_choice(tmp_path):
    args = small_args("discrete", tmp_path)
    run_dir = train(ppo_pgg_discrete, args)
    with pytest.raises(runs.RunDirError, match="holds a finished run: pass --overwrite"):
        prepare(ppo_pgg_discrete, args)
    checkpoints.checkpoint_path(run_dir, 1536).unlink()
    with pytest.raises(runs.RunDirError, match=r"unfinished run \(last checkpoint step_000001024.pt\): pass --resume"):
        prepare(ppo_pgg_discrete, args)
    train(ppo_pgg_discrete, replace(args, overwrite=True, total_timesteps=512, checkpoint_interval=512))
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["step_000000512.pt"]


def test_a_run_directory_in_use_is_refused(tmp_path):
    run_dir = tmp_path / "busy"
    run_dir.mkdir()
    lock = lock_directory(run_dir)
    try:
        line = one_line_error(run_here("discrete", "--output-dir", str(tmp_path), "--run-name", "busy"))
        assert f"{run_dir} is in use by another process (pid {os.getpid()})" in line
    finally:
        lock.close()
    # The lock went with its holder: the directory is free again.
    lock_directory(run_dir).close()


# --- interaction ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_ctrl_c_exits_130_with_one_line_saying_what_is_kept(tmp_path):
    script = ROOT / "ppo_pgg_discrete.py"
    flags = ["--output-dir", str(tmp_path), "--run-name", "stopped", "--checkpoint-interval", "2048"]
    proc = subprocess.Popen([sys.executable, str(script), *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=default_sigint)  # fmt: skip
    first = tmp_path / "stopped" / "checkpoints" / "step_000002048.pt"
    deadline = time.time() + 120
    while not first.exists() and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    try:
        _, stderr = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"SIGINT did not stop training: {proc.communicate()}")
    lines = stderr.strip().splitlines()
    assert proc.returncode == 130 and len(lines) == 1 and "Traceback" not in stderr, stderr
    assert "checkpoints up to step_0000" in lines[0] and "--resume" in lines[0]


@pytest.mark.slow
def test_progress_is_a_live_bar_in_a_terminal_and_plain_lines_in_a_log(tmp_path, capsys):
    report = progress.Progress("training", 1000, 0, unit="steps", interval=0.0)
    report.update(500, "123 SPS  return(last 20) 15.0")
    report.close()
    line = capsys.readouterr().out.strip()
    assert line.startswith("training: 500/1,000 steps  123 SPS  return(last 20) 15.0  ETA ")

    flags = ["--output-dir", str(tmp_path), "--total-timesteps", "4096", "--checkpoint-interval", "4096"]
    command = [sys.executable, str(ROOT / "ppo_pgg_discrete.py"), *flags]
    controller, terminal = pty.openpty()
    proc = subprocess.Popen(
        command, stdin=terminal, stdout=terminal, stderr=terminal, env=dict(os.environ, COLUMNS="250")
    )
    os.close(terminal)
    output = b""
    while True:
        try:
            chunk = os.read(controller, 4096)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        output += chunk
    assert proc.wait(timeout=60) == 0
    screen = output.decode(errors="replace")
    assert "training" in screen and "━" in screen and "4,096/4,096 steps" in screen and "SPS" in screen


@pytest.mark.slow
def test_capture_video_records_the_first_sub_envs_episodes(tmp_path):
    pytest.importorskip("moviepy", reason="--capture-video needs the [video] extra")
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    import imageio.v3 as iio
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    args = ppo_pgg_discrete.Args(output_dir=str(tmp_path), total_timesteps=512, checkpoint_interval=512, num_envs=1,
                                 num_steps=512, capture_video=True)  # fmt: skip
    assert checks.argument_error(args, "discrete") is None
    run_dir = train(ppo_pgg_discrete, args)
    first = run_dir / "videos" / "rl-video-episode-0.mp4"
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    length = int(events.Scalars("charts/episodic_length")[0].value)
    assert first.stat().st_size > 0
    assert sum(1 for _ in iio.imiter(first)) == length + 1  # the reset frame and one per step


@pytest.mark.slow
def test_capture_video_without_a_renderer_is_one_line(tmp_path):
    proc = run_training(
        "continuous", "--env-id", "Hopper-v4", "--capture-video", "--output-dir", str(tmp_path / "runs"),
        env=dict(os.environ, MUJOCO_GL="no-such-backend"),
    )  # fmt: skip
    assert "MUJOCO_GL" in one_line_error(proc) and not (tmp_path / "runs").exists()


# --- PPO statistics under conditioning dropout ---------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_kl_statistics_cover_kept_rows_only(kind):
    """At the first minibatch of an iteration the policy has not moved: the kept rows' ratio is 1 and
    their KL estimates ≈ 0, while dropped rows compare pi(a|null) with the pi_hat(a|s) that acted."""
    module = SCRIPTS[kind]
    torch.manual_seed(0)
    obs_dim, action_dim = 4, 2
    if kind == "discrete":
        agent = module.Agent(obs_dim, action_dim)
        buf = module.Rollout.empty(256, 1, obs_dim)
    else:
        agent = module.Agent(obs_dim, action_dim)
        buf = module.Rollout.empty(256, 1, obs_dim, action_dim)
    with torch.no_grad():
        for layer in agent.modules():
            if isinstance(layer, torch.nn.Linear):
                layer.weight.normal_(0, 1.0)  # a policy far from uniform, so dropped rows really differ
    buf.obs.normal_()
    policy = module.FastPolicy(agent, 1.1)
    noise = (
        module.gumbel_noise(256, action_dim)
        if kind == "discrete"
        else np.random.default_rng(0).standard_normal((256, action_dim))
    )
    actions, logprobs, _ = policy.act(buf.obs[:, 0].numpy(), noise)
    buf.actions[:, 0] = torch.as_tensor(actions)
    buf.logprobs[:, 0] = torch.as_tensor(logprobs)
    args = module.Args(guidance=1.1, cond_dropout=0.3, num_minibatches=1)
    batch = {"obs": buf.obs[:, 0], "actions": buf.actions[:, 0], "logprobs": buf.logprobs[:, 0],
             "advantages": torch.randn(256), "returns": torch.randn(256), "values": torch.zeros(256)}  # fmt: skip
    drop_mask = torch.rand(256) < args.cond_dropout
    _, stats = module.minibatch_loss(agent, batch, torch.arange(256), drop_mask, torch.tensor(args.guidance), args)
    assert abs(stats["losses/approx_kl"].item()) < 1e-6 and abs(stats["losses/old_approx_kl"].item()) < 1e-5
    assert stats["losses/clipfrac"].item() == 0.0
    assert (
        stats["pgg/dropped_abs_logratio"].item() > 0.05
        and stats["pgg/dropped_fraction"].item() == drop_mask.float().mean()
    )


# --- faults a newcomer found ---------------------------------------------------------------------


def launch(module, args, capsys) -> tuple[int, list[str]]:
    """A training script's main after parsing, in this process: (exit status, stderr lines)."""
    try:
        runs.launch(args, module.ACTION_SPACE, module.__file__, module.train)
        code = 0
    except SystemExit as e:
        code = e.code
    return code, capsys.readouterr().err.strip().splitlines()


def test_a_task_whose_state_holds_numpy_scalars_writes_checkpoints_that_load_and_resume(tmp_path):
    """MountainCar keeps its state as a tuple of np.float64, which a weights-only checkpoint cannot
    hold as such; stopped and resumed, the run still ends on the uninterrupted run's bits."""
    args = small_args("discrete", tmp_path, env_id="MountainCar-v0", run_name="straight")
    straight = train(ppo_pgg_discrete, args)
    ppo_pgg_discrete.load_checkpoint(checkpoints.checkpoint_path(straight, 512))
    stopped = tmp_path / "stopped"
    shutil.copytree(straight, stopped)
    for later in (1024, 1536):
        checkpoints.checkpoint_path(stopped, later).unlink()
    train(ppo_pgg_discrete, replace(args, run_name="stopped", resume=True))
    a, b = checkpoint(straight, 1536), checkpoint(stopped, 1536)
    assert all(torch.equal(a["model"][key], b["model"][key]) for key in a["model"])


def test_a_checkpoint_that_would_not_load_back_stops_the_run_at_the_first_one(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(training_state, "pickle_free", lambda value: value)  # numpy arrays go in as they are
    code, error = launch(ppo_pgg_discrete, small_args("discrete", tmp_path), capsys)
    assert code == 1 and len(error) == 1 and "step_000000512.pt" in error[0] and "would not load back" in error[0]
    assert not list(tmp_path.rglob("step_*.pt")) and not list(tmp_path.rglob("*.tmp"))


@pytest.mark.parametrize(
    "kind,flags", [("discrete", ["--num-steps", "1"]), ("continuous", ["--num-minibatches", "2048"])]
)
def test_minibatches_too_small_to_normalise_advantages_are_refused(kind, flags, tmp_path):
    line = one_line_error(run_here(kind, "--output-dir", str(tmp_path / "runs"), *flags))
    assert "cannot normalise advantages" in line and "--no-norm-adv" in line
    assert not (tmp_path / "runs").exists()


def test_a_non_finite_update_stops_the_run_naming_the_iteration_and_keeps_the_finite_checkpoints(
    tmp_path, monkeypatch, capsys
):
    real_update, calls = ppo_pgg_discrete.ppo_update, []

    def diverges_at_the_third(agent, *rest, **kwargs):
        stats = real_update(agent, *rest, **kwargs)
        calls.append(1)
        if len(calls) == 3:
            with torch.no_grad():
                agent.actor[0].weight[0, 0] = float("nan")
        return stats

    monkeypatch.setattr(ppo_pgg_discrete, "ppo_update", diverges_at_the_third)
    args = small_args("discrete", tmp_path)
    code, error = launch(ppo_pgg_discrete, args, capsys)
    assert code == 1 and len(error) == 1, error
    assert "iteration 3 (global step 768): non-finite weights; checkpoints up to step_000000512.pt are kept" in error[0]
    run_dir = tmp_path / default_run_name(args)
    assert [p.name for p in checkpoints.checkpoints_of(run_dir)] == ["step_000000512.pt"]
    # A checkpoint with non-finite weights (from elsewhere) is never continued.
    ckpt = checkpoint(run_dir, 512)
    ckpt["model"]["null_obs"][0] = float("nan")
    torch.save(ckpt, checkpoints.checkpoint_path(run_dir, 512))
    with pytest.raises(runs.RunDirError, match="non-finite weights"):
        prepare(ppo_pgg_discrete, replace(args, resume=True))


def test_resume_sets_an_unreadable_last_checkpoint_aside_and_continues_from_the_one_before(tmp_path, capsys):
    args = small_args("discrete", tmp_path, run_name="straight")
    straight = train(ppo_pgg_discrete, args)
    stopped = tmp_path / "stopped"
    shutil.copytree(straight, stopped)
    checkpoints.checkpoint_path(stopped, 1536).unlink()
    truncated = checkpoints.checkpoint_path(stopped, 1024)
    truncated.write_bytes(truncated.read_bytes()[:1000])
    with pytest.raises(runs.RunDirError, match="pass --resume to continue from the last readable checkpoint"):
        prepare(ppo_pgg_discrete, replace(args, run_name="stopped"))
    code, error = launch(ppo_pgg_discrete, replace(args, run_name="stopped", resume=True), capsys)
    assert code == 0 and any("set aside step_000001024.pt.unreadable" in line for line in error)
    assert (truncated.parent / "step_000001024.pt.unreadable").exists()  # kept, not deleted
    a, b = checkpoint(straight, 1536), checkpoint(stopped, 1536)
    assert all(torch.equal(a["model"][key], b["model"][key]) for key in a["model"])


def test_resuming_a_finished_run_touches_none_of_its_files(tmp_path):
    args = small_args("discrete", tmp_path, total_timesteps=512)
    run_dir = train(ppo_pgg_discrete, args)
    before = {path: path.read_bytes() for path in run_dir.rglob("*") if path.is_file() and path.name != ".lock"}
    proc = run_here("discrete", "--output-dir", str(tmp_path), "--run-name", run_dir.name, "--total-timesteps", "512",
                        "--checkpoint-interval", "512", "--num-steps", "64", "--guidance", "1.1", "--cond-dropout", "0.1",
                        "--resume", "--torch-threads", "2")  # fmt: skip
    assert proc.returncode == 0 and "nothing to train" in proc.stdout, proc.stderr
    assert {path: path.read_bytes() for path in before} == before


@pytest.mark.parametrize("name", ["../escape", "/tmp/absolute", ".", "..", "a/b", "", " ", "run ", "a\nb"])
def test_a_run_name_is_one_path_component(name, tmp_path):
    line = one_line_error(run_here("discrete", "--output-dir", str(tmp_path / "runs"), "--run-name", name))
    assert "--run-name must be one path component" in line or "--run-name must be printable" in line
    assert not list(tmp_path.iterdir()) and not Path("/tmp/absolute").exists()


@pytest.mark.parametrize("env_id,space", [("FrozenLake-v1", "Discrete"), ("Blackjack-v1", "Tuple")])
def test_a_task_without_a_vector_observation_is_refused_before_touching_the_disk(env_id, space, tmp_path):
    line = one_line_error(run_here("discrete", "--env-id", env_id, "--output-dir", str(tmp_path / "runs")))
    assert f"{space} observation space" in line and not (tmp_path / "runs").exists()


def test_dropping_every_row_is_refused(tmp_path):
    """At --cond-dropout 1 no row keeps its state: the KL and clip fraction of the kept rows are of none
    (logged as 0.0, so --target-kl could never fire), and the policy never sees a state."""
    line = one_line_error(run_here("discrete", "--cond-dropout", "1", "--total-timesteps", "512",
                                       "--output-dir", str(tmp_path / "runs")))  # fmt: skip
    assert line == "error: --cond-dropout must be in [0, 1) (at 1 no row keeps its state), got 1.0"
    assert not (tmp_path / "runs").exists()


def test_an_eta_reads_in_minutes_and_seconds():
    assert [progress.format_duration(s) for s in (100, 3599, 3600, 7325)] == ["1m40s", "59m59s", "1h00m", "2h02m"]


def test_a_full_disk_under_tensorboard_is_one_line_naming_the_events_file(tmp_path, monkeypatch, capsys):
    from tensorboard.summary.writer import record_writer

    real_write, writes = record_writer.RecordWriter.write, []

    def full_after_three(self, data):
        writes.append(1)
        if len(writes) > 3:
            raise OSError(28, "No space left on device")
        return real_write(self, data)

    monkeypatch.setattr(record_writer.RecordWriter, "write", full_after_three)
    args = small_args("discrete", tmp_path)
    code, error = launch(ppo_pgg_discrete, args, capsys)
    assert code == 1 and len(error) == 1, error
    (events,) = (tmp_path / default_run_name(args)).glob("events.out.tfevents.*")
    assert error[0] == f"error: cannot write {events}: No space left on device"


def test_a_refused_resume_sets_nothing_aside(tmp_path):
    """Every check runs before anything is renamed: a --resume with other arguments is refused and the
    unreadable checkpoint stays where it was."""
    args = small_args("discrete", tmp_path)
    run_dir = train(ppo_pgg_discrete, args)
    last = checkpoints.checkpoint_path(run_dir, 1536)
    last.write_bytes(b"not a checkpoint")
    with pytest.raises(runs.RunDirError, match="other arguments"):
        prepare(ppo_pgg_discrete, replace(args, resume=True, learning_rate=0.002))
    assert last.read_bytes() == b"not a checkpoint" and not list(run_dir.rglob("*.unreadable"))


@pytest.mark.slow
def test_resuming_with_capture_video_switched_on_still_ends_on_the_uninterrupted_runs_bits(tmp_path):
    """RecordVideo joins the first sub-env's wrapper chain; the saved wrapper state is matched by kind."""
    pytest.importorskip("moviepy", reason="--capture-video needs the [video] extra")
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    args = small_args("discrete", tmp_path, run_name="straight")
    straight = train(ppo_pgg_discrete, args)
    stopped = tmp_path / "stopped"
    shutil.copytree(straight, stopped)
    for later in (1024, 1536):
        checkpoints.checkpoint_path(stopped, later).unlink()
    train(ppo_pgg_discrete, replace(args, run_name="stopped", resume=True, capture_video=True))
    a, b = checkpoint(straight, 1536), checkpoint(stopped, 1536)
    assert all(torch.equal(a["model"][key], b["model"][key]) for key in a["model"])
    assert list((stopped / "videos").rglob("*.mp4"))


# --- both scripts --------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_compile_flag_trains_through_the_compiled_loss(kind, tmp_path, compiled_calls):
    module = SCRIPTS[kind]
    args = small_args(kind, tmp_path, guidance=1.1, cond_dropout=0.25, total_timesteps=256, checkpoint_interval=256)
    eager = checkpoint(train(module, args), 256)["model"]
    compiled = checkpoint(train(module, replace(args, compile=True, run_name="compiled")), 256)["model"]
    assert compiled_calls == [module.minibatch_loss] * (args.update_epochs * args.num_minibatches)
    for key, value in eager.items():  # one iteration's Adam steps: the same update to float rounding
        torch.testing.assert_close(compiled[key], value, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(
    "kind,flags,message",
    [
        ("discrete", ["--env-id", "NoSuchEnv-v0"], "cannot make environment"),
        ("discrete", ["--env-id", "Pendulum-v1"], "Box action space"),
        ("discrete", ["--guidance", "nan"], "--guidance"),
        ("discrete", ["--guidance", "-1"], "--guidance"),
        ("discrete", ["--cond-dropout", "1.5"], "--cond-dropout"),
        ("discrete", ["--checkpoint-interval", "0"], "--checkpoint-interval"),
        ("discrete", ["--output-dir", "/proc/forbidden"], "cannot write the run directory"),
        pytest.param("discrete", ["--compile"], "--compile needs a C++ compiler", marks=pytest.mark.slow),  # no CXX
        ("continuous", ["--env-id", "CartPole-v1"], "Discrete action space"),
        ("continuous", ["--env-id", "Nope-v4"], "cannot make environment"),
        ("continuous", ["--guidance", "inf"], "--guidance"),
        ("continuous", ["--cond-dropout", "-0.1"], "--cond-dropout"),
        ("continuous", ["--checkpoint-interval", "-5"], "--checkpoint-interval"),
        pytest.param("continuous", ["--compile"], "--compile needs a C++ compiler", marks=pytest.mark.slow),
    ],
)
def test_bad_input_exits_with_one_line(kind, flags, message):
    if flags != ["--compile"]:
        assert message in one_line_error(run_here(kind, *flags))
        return
    no_compiler = {key: value for key, value in os.environ.items() if key != "CXX"} | {"PATH": ""}
    assert message in one_line_error(run_training(kind, *flags, env=no_compiler))


# --- what a newcomer broke, round three (issue 46) -----------------------------------------------


def test_a_fresh_start_never_deletes_a_file_the_scripts_did_not_write(tmp_path):
    """An earlier start's events and videos are not replaced without --overwrite (or --resume of the same
    run); --overwrite removes only what the scripts wrote, never a user's files beside them."""
    args = small_args("discrete", tmp_path, total_timesteps=512, checkpoint_interval=512, run_name="r")
    run_dir = tmp_path / "r"
    (run_dir / "videos").mkdir(parents=True)
    (run_dir / "videos" / "holiday.mp4").write_bytes(b"mine")
    (run_dir / "events.out.tfevents.1.old").write_bytes(b"an earlier start's curve")
    with pytest.raises(
        runs.RunDirError, match="holds TensorBoard events of an earlier start that reached no checkpoint"
    ):
        prepare(ppo_pgg_discrete, args)
    assert sorted(p.name for p in run_dir.rglob("*") if p.is_file()) == [".lock", "events.out.tfevents.1.old",
                                                                         "holiday.mp4"]  # fmt: skip
    train(ppo_pgg_discrete, replace(args, overwrite=True))
    (run_dir / "checkpoints" / "my_notes.txt").write_text("notes")
    (run_dir / "checkpoints" / "step_best.pt").write_bytes(checkpoints.checkpoint_path(run_dir, 512).read_bytes())
    train(ppo_pgg_discrete, replace(args, overwrite=True))
    assert (run_dir / "videos" / "holiday.mp4").read_bytes() == b"mine"
    assert (run_dir / "checkpoints" / "my_notes.txt").read_text() == "notes" and (
        run_dir / "checkpoints" / "step_best.pt"
    ).exists()
    assert (
        not (run_dir / "events.out.tfevents.1.old").exists() and len(list(run_dir.glob("events.out.tfevents.*"))) == 1
    )


def test_resume_restarts_a_run_that_reached_no_checkpoint_only_if_it_is_the_same_run(tmp_path):
    """As the launcher does after a kill before the first checkpoint: --resume replaces the events of the
    same run's start (by its args.json), and refuses those of another."""
    args = small_args("discrete", tmp_path, total_timesteps=512, checkpoint_interval=512, run_name="r")
    run_dir = train(ppo_pgg_discrete, args)
    checkpoints.checkpoint_path(run_dir, 512).unlink()
    with pytest.raises(runs.RunDirError, match=r"of a run with other arguments \(learning_rate"):
        prepare(ppo_pgg_discrete, replace(args, resume=True, learning_rate=0.002))
    train(ppo_pgg_discrete, replace(args, resume=True))
    assert checkpoints.checkpoint_path(run_dir, 512).exists() and len(list(run_dir.glob("events.out.tfevents.*"))) == 1


def test_an_args_json_that_disagrees_with_the_checkpoints_is_refused(tmp_path):
    args = small_args("discrete", tmp_path, total_timesteps=512, checkpoint_interval=512)
    run_dir = train(ppo_pgg_discrete, args)
    edited = (run_dir / "args.json").read_text().replace("CartPole-v1", "Acrobot-v1")
    (run_dir / "args.json").write_text(edited)
    expected = (f"{run_dir / 'args.json'} disagrees with the run's checkpoints: env_id 'Acrobot-v1' (checkpoints: "
                "'CartPole-v1')")  # fmt: skip
    assert runs.record_error(run_dir) == expected
    with pytest.raises(runs.RunDirError, match="disagrees with the run's checkpoints"):
        prepare(ppo_pgg_discrete, replace(args, resume=True))
    assert (run_dir / "args.json").read_text() == edited


def test_a_name_built_from_exp_name_is_one_path_component(tmp_path):
    output = tmp_path / "a" / "b" / "runs"
    line = one_line_error(run_here("discrete", "--exp-name", "x/../../../esc_outside", "--output-dir", str(output)))
    assert "the run name built from --env-id and --exp-name must be one path component" in line
    assert not list(tmp_path.iterdir())


def test_a_namespaced_id_makes_one_path_component_and_other_names_are_unchanged():
    assert default_run_name(ppo_pgg_discrete.Args(env_id="mymod:ns/Env-v0")) == "mymod-ns-Env-v0__ppo_pgg__g1__p0__s1"
    assert default_run_name(ppo_pgg_discrete.Args(guidance=1.1, seed=3)) == "CartPole-v1__ppo_pgg__g1.1__p0__s3"


def test_a_misnamed_checkpoint_is_skipped_with_a_line_by_the_resume_and_the_sweep(tmp_path, capsys):
    args = small_args("discrete", tmp_path, total_timesteps=1024, checkpoint_interval=512)
    run_dir = train(ppo_pgg_discrete, args)
    checkpoints.checkpoint_path(run_dir, 1024).unlink()
    misnamed = run_dir / "checkpoints" / "step_abc.pt"
    misnamed.touch()
    code, error = launch(ppo_pgg_discrete, replace(args, resume=True), capsys)
    assert code == 0 and f"note: {misnamed}: not a checkpoint's name (step_<digits>.pt); left as it is" in error
    assert misnamed.exists() and checkpoints.checkpoint_path(run_dir, 1024).exists()
    skipped = []
    assert checkpoints.find_checkpoints([run_dir], skipped=skipped) == checkpoints.checkpoints_of(run_dir)
    assert skipped == [f"{misnamed}: not a checkpoint's name (step_<digits>.pt); left as it is"]


class EmptyObservation(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (0,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, render_mode=None):
        self.render_mode = render_mode


def test_an_empty_observation_space_is_refused_before_training():
    gym.register("EmptyObservation-v0", entry_point=EmptyObservation)
    try:
        error = checks.env_error("EmptyObservation-v0", "discrete")
    finally:
        del gym.registry["EmptyObservation-v0"]
    assert error == "EmptyObservation-v0 has an empty observation space (shape (0,)): there is no state to condition on"


@pytest.mark.parametrize("script", ["ppo_pgg_discrete.py", "eval_gamma_sweep.py"])
def test_ctrl_c_while_importing_is_one_line_and_status_130(script, tmp_path):
    """SIGINT while torch is being imported (its library is mapped, the import not finished)."""
    proc = subprocess.Popen([sys.executable, str(ROOT / script), "--output-dir", str(tmp_path / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)  # fmt: skip
    maps, deadline = Path(f"/proc/{proc.pid}/maps"), time.time() + 60
    while "libtorch" not in maps.read_text() and time.time() < deadline:
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130 and stderr.strip() == "interrupted while starting", stderr
    assert not (tmp_path / "out").exists()


# --- a configuration built once (issue 50) --------------------------------------------------------------

FORK_ARGUMENT = """    my_coef: float = 0.5
    \"\"\"a fork's new loss coefficient\"\"\"
"""


def fork(folder: Path, name: str = "ppo_fork.py") -> Path:
    """A copy of the discrete script, outside the repository, with a new training argument."""
    text = (ROOT / "ppo_pgg_discrete.py").read_text()
    anchor = "    total_timesteps: int"
    assert anchor in text
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(text.replace(anchor, FORK_ARGUMENT + anchor, 1))
    return folder / name


def run_fork(script: Path, *flags) -> subprocess.CompletedProcess:
    """A fork outside the repository runs with this checkout's package, as an installed project's would."""
    return subprocess.run([sys.executable, str(script), *flags], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), check=False)  # fmt: skip


TINY = ["--total-timesteps", "512", "--num-envs", "1", "--num-steps", "128", "--checkpoint-interval", "256"]


@pytest.mark.slow
def test_a_fork_and_each_value_of_its_new_argument_get_a_run_directory_of_their_own(tmp_path):
    script, output = fork(tmp_path / "elsewhere"), tmp_path / "runs"
    for value in ("0.5", "0.7"):  # the fork imported as the sweep imports it, its main run in this process
        proc = run_main(scripts.load_module(script), *TINY, "--my-coef", value, "--output-dir", str(output))
        assert proc.returncode == 0, proc.stderr[-2000:]
    original = run_main(ppo_pgg_discrete, *TINY, "--output-dir", str(output))
    assert original.returncode == 0, original.stderr[-2000:]
    assert sorted(p.name for p in output.iterdir()) == [
        "CartPole-v1__ppo_fork__g1__p0__my_coef0.5__s1",  # the script's file stem, as CleanRL's --exp-name
        "CartPole-v1__ppo_fork__g1__p0__my_coef0.7__s1",
        "CartPole-v1__ppo_pgg__g1__p0__s1",  # the repository's scripts' runs keep their names
    ]
    recorded = checkpoint(output / "CartPole-v1__ppo_fork__g1__p0__my_coef0.7__s1", 512)
    assert recorded["args"]["exp_name"] == "ppo_fork__ppo" and recorded["args"]["my_coef"] == 0.7  # W&B's grouping
    assert checkpoint(output / "CartPole-v1__ppo_pgg__g1__p0__s1", 512)["args"]["exp_name"] == "ppo_pgg_discrete__ppo"


@pytest.mark.slow
def test_resume_refuses_a_run_another_script_trained_and_says_when_the_script_changed(tmp_path):
    script, output = fork(tmp_path / "elsewhere"), tmp_path / "runs"
    common = [*TINY, "--output-dir", str(output), "--run-name", "shared"]
    assert run_script("ppo_pgg_discrete.py", *common).returncode == 0
    checkpoints.checkpoint_path(output / "shared", 512).unlink()
    proc = run_fork(script, *common, "--resume")
    line = one_line_error(proc)
    assert "a run that ppo_pgg_discrete.py trained, not ppo_fork.py" in line
    assert not checkpoints.checkpoint_path(output / "shared", 512).exists()

    own = [*TINY, "--output-dir", str(output), "--run-name", "forked"]
    assert run_fork(script, *own).returncode == 0
    checkpoints.checkpoint_path(output / "forked", 512).unlink()
    script.write_text(script.read_text() + "\n# an edit after the first checkpoint\n")
    proc = run_fork(script, *own, "--resume")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "note: ppo_fork.py has changed since step_000000256.pt was written" in proc.stderr
    assert (
        checkpoint(output / "forked", 512)["code"]["script_sha1"]
        != checkpoint(output / "forked", 256)["code"]["script_sha1"]
    )


def test_resume_compares_what_the_label_compares_an_argument_an_older_checkpoint_lacks_at_its_frozen_default():
    recorded = identity.Configuration("discrete", "ppo_pgg_discrete.py", {"env_id": "CartPole-v1", "seed": 1})
    wanted = identity.Configuration.of_run(ROOT / "ppo_pgg_discrete.py", "discrete", ppo_pgg_discrete.Args())
    defaults = vars(ppo_pgg_discrete.Args())
    assert recorded.differing(wanted, defaults) == []
    changed = identity.Configuration.of_run(
        ROOT / "ppo_pgg_discrete.py", "discrete", ppo_pgg_discrete.Args(discount=0.9)
    )
    assert recorded.differing(changed, defaults) == ["discount 0.99 -> 0.9"]


def test_the_project_modules_import_one_another_in_no_circle():
    """identity, runs and scripts imported one another in a circle; every import counts, those inside functions too."""
    import ast

    graph = {}
    for path in (ROOT / "pgg_utils").glob("*.py"):
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "pgg_utils":
                imported |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("pgg_utils."):
                imported.add(node.module.split(".")[1])
        graph[path.stem] = imported

    def reaches(start: str, target: str, seen: set) -> bool:
        return any(d == target or (d not in seen and reaches(d, target, seen | {d})) for d in graph.get(start, ()))

    assert [module for module in graph if reaches(module, module, {module})] == []


# --- a script that changes its args while training ------------------------------------------------

# CleanRL's habit for a schedule: the argument itself rewritten in the training loop, here halved every iteration.
ENTROPY_SCHEDULE = "            args.ent_coef *= 0.5  # an entropy schedule\n"


def test_a_script_that_changes_its_args_while_training_is_one_configuration_and_resumes_exactly(tmp_path):
    """An entropy schedule written `args.ent_coef *= 0.5` in the loop: every checkpoint records the arguments the run
    started with, as args.json does, so the sweep sees one configuration; the values the script reached are resume
    state, so a run stopped and resumed ends on the uninterrupted run's bits. Today's main recorded each checkpoint's
    current value (one run, three configurations) and its --resume blamed args.json."""
    source = (ROOT / "ppo_pgg_discrete.py").read_text()
    loop_top = "            if args.anneal_lr:\n"
    assert source.count(loop_top) == 1
    script = tmp_path / "ppo_entropy_schedule.py"
    script.write_text(source.replace(loop_top, ENTROPY_SCHEDULE + loop_top))
    module = scripts.load_module(script)
    args = module.Args(**vars(small_args("discrete", tmp_path / "runs", run_name="straight")))
    straight = runs.train_in_process(module, args)
    started = json.loads((straight / "args.json").read_text())
    for mark, iteration in ((512, 2), (1024, 4), (1536, 6)):
        ckpt = checkpoint(straight, mark)
        assert runs.as_json(ckpt["args"]) == started and ckpt["args"]["ent_coef"] == 0.01
        assert ckpt["resume"]["changed_arguments"] == {"ent_coef": 0.01 * 0.5**iteration}
    sweep.sweep(sweep.Args(paths=(str(straight),), output=str(tmp_path / "sweep"), gammas=(1.0,), episodes=1,
                           script=(str(script),)))  # fmt: skip
    assert len({row["config"] for row in files.read_csv(tmp_path / "sweep" / "summary.csv")}) == 1

    stopped = tmp_path / "runs" / "stopped"
    (stopped / "checkpoints").mkdir(parents=True)
    shutil.copy(straight / "args.json", stopped / "args.json")
    for mark in (512, 1024):
        shutil.copy(checkpoints.checkpoint_path(straight, mark), checkpoints.checkpoint_path(stopped, mark))
    runs.train_in_process(module, replace(args, run_name="stopped", resume=True))
    resumed, uninterrupted = checkpoint(stopped, 1536), checkpoint(straight, 1536)
    assert all(torch.equal(resumed["model"][k], uninterrupted["model"][k]) for k in uninterrupted["model"])
    assert resumed["resume"]["changed_arguments"] == uninterrupted["resume"]["changed_arguments"]
