"""Run directories and checkpoints of both training scripts: resume, refusal to overwrite, the lock,
one-line errors, Ctrl-C, progress, videos, and the PPO statistics under conditioning dropout."""

import os
import pty
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch

import ppo_pgg_continuous
import ppo_pgg_discrete
from conftest import ROOT

SCRIPTS = {"discrete": ppo_pgg_discrete, "continuous": ppo_pgg_continuous}


def small_args(kind: str, tmp_path, **overrides):
    module = SCRIPTS[kind]
    base = {
        "discrete": dict(total_timesteps=1536, checkpoint_interval=512, num_steps=64),
        # Humanoid: the task whose observation and reward read quantities MuJoCo derives a step late.
        "continuous": dict(env_id="Humanoid-v4", total_timesteps=768, checkpoint_interval=256, num_steps=256,
                           num_minibatches=4, update_epochs=2),
    }[kind]  # fmt: skip
    return replace(module.Args(output_dir=str(tmp_path), guidance=1.1, cond_dropout=0.1, **base), **overrides)


def train(module, args):
    run_dir = module.prepare_run_dir(args)
    module.train(args, run_dir)
    return run_dir


def checkpoint(module, run_dir, mark) -> dict:
    return torch.load(module.checkpoint_path(run_dir, mark), weights_only=True)


def run_script(kind: str, *flags, **kwargs) -> subprocess.CompletedProcess:
    script = ROOT / f"{SCRIPTS[kind].__name__}.py"
    return subprocess.run([sys.executable, str(script), *flags], capture_output=True, text=True, timeout=300, **kwargs)


def one_line_error(proc: subprocess.CompletedProcess, code: int = 2) -> str:
    """The one line of error, besides gymnasium's expected two-line notice that v4 tasks are old."""
    lines = [line for line in proc.stderr.strip().splitlines() if "DeprecationWarning" not in line and "logger.deprecation(" not in line]
    assert proc.returncode == code and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


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
    for later in module.checkpoint_path(stopped, first).parent.glob("*.pt"):
        if later.name > module.checkpoint_path(stopped, first).name:
            later.unlink()
    resumed = train(module, replace(args, run_name="stopped", resume=True))
    a, b = checkpoint(module, straight, last), checkpoint(module, resumed, last)
    assert a["model"].keys() == b["model"].keys()
    assert all(torch.equal(a["model"][key], b["model"][key]) for key in a["model"])
    assert torch.equal(a["resume"]["optimizer"]["state"][0]["exp_avg"], b["resume"]["optimizer"]["state"][0]["exp_avg"])
    assert a["resume"]["iteration"] == b["resume"]["iteration"] and a["global_step"] == b["global_step"]


def test_resume_continues_the_learning_rate_schedule_and_purges_later_events(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    args = small_args("discrete", tmp_path, cond_dropout=0.0)
    run_dir = train(ppo_pgg_discrete, args)
    ppo_pgg_discrete.checkpoint_path(run_dir, 1536).unlink()  # as if stopped after the 1024 checkpoint
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
    path = ppo_pgg_discrete.checkpoint_path(run_dir, 512)
    old = checkpoint(ppo_pgg_discrete, run_dir, 512)
    old = {key: value for key, value in old.items() if key not in ("resume", "versions")} | {"format_version": 1}
    torch.save(old, path)
    ppo_pgg_discrete.checkpoint_path(run_dir, 1024).unlink()
    agent, ckpt = ppo_pgg_discrete.load_checkpoint(path)
    assert ckpt["format_version"] == 1 and torch.equal(agent.null_obs, old["model"]["null_obs"])
    with pytest.raises(ppo_pgg_discrete.RunDirError, match="predates resumable checkpoints"):
        ppo_pgg_discrete.prepare_run_dir(replace(args, resume=True))
    assert path.exists()


def test_one_checkpoint_per_saved_iteration():
    """A mark that the last iteration passes is left to the total's checkpoint: interval 3900 of a
    4000-step run of 512-step batches would otherwise write step_3900 and step_4000 at one point."""
    assert ppo_pgg_discrete.checkpoint_marks(4000, 3900, 512) == [4000]
    assert ppo_pgg_continuous.checkpoint_marks(2500, 1024, 256) == [1024, 2048, 2500]


def test_a_failed_checkpoint_write_leaves_the_previous_ones_whole(tmp_path, monkeypatch):
    """A checkpoint is written to a temporary file and renamed: a write that dies half way (full disk,
    kill) leaves no step_*.pt behind and the earlier checkpoints as they were."""
    args = small_args("discrete", tmp_path)
    real_save = torch.save

    def dies_at_the_second(payload, path):
        if payload["step_mark"] == 1024:
            with open(path, "wb") as f:
                f.write(b"half a checkpoint")
            raise OSError(28, "No space left on device")
        real_save(payload, path)

    monkeypatch.setattr(torch, "save", dies_at_the_second)
    with pytest.raises(OSError):
        train(ppo_pgg_discrete, args)
    run_dir = tmp_path / ppo_pgg_discrete.default_run_name(args)
    assert sorted(p.name for p in (run_dir / "checkpoints").glob("step_*.pt")) == ["step_000000512.pt"]
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
    envs = ppo_pgg_continuous.make_vector_env("Drift", 1, seed=0, discount=0.99, reward_clip=10.0)
    envs.reset(seed=0)
    for _ in range(5):
        envs.step(np.full((1, 1), 0.5, np.float32))
    states = ppo_pgg_continuous.env_state(envs)
    assert states[0]["complete"] is False
    fresh = ppo_pgg_continuous.make_vector_env("Drift", 1, seed=0, discount=0.99, reward_clip=10.0)
    fresh.reset(seed=1)
    ppo_pgg_continuous.restore_env_state(fresh, states)
    saved, restored = (next(w for w in ppo_pgg_continuous.wrapper_chain(e.envs[0]) if isinstance(w, ppo_pgg_continuous.NormalizeClipReward))
                       for e in (envs, fresh))  # fmt: skip
    assert restored.return_count == saved.return_count == 1e-4 + 5 and restored.return_var == saved.return_var


def test_checkpoint_records_the_software_stack(tmp_path):
    ckpt = checkpoint(ppo_pgg_discrete, train(ppo_pgg_discrete, small_args("discrete", tmp_path, total_timesteps=512)), 512)
    assert ckpt["versions"]["torch"] == torch.__version__ and ckpt["versions"]["gymnasium"]


# --- a run directory is never destroyed or shared ------------------------------------------------


def test_rerun_with_other_arguments_is_refused_before_touching_the_run(tmp_path):
    args = small_args("discrete", tmp_path, total_timesteps=1024)
    run_dir = train(ppo_pgg_discrete, args)
    before = {path: path.read_bytes() for path in run_dir.rglob("*") if path.is_file() and path.name != ".lock"}
    proc = run_script(
        "discrete", "--output-dir", str(tmp_path), "--run-name", run_dir.name, "--total-timesteps", "1024",
        "--checkpoint-interval", "512", "--num-steps", "64", "--guidance", "1.1", "--cond-dropout", "0.1",
        "--learning-rate", "0.002",
    )  # fmt: skip
    line = one_line_error(proc)
    assert str(run_dir) in line and "learning_rate 0.00025 -> 0.002" in line and "--overwrite" in line
    assert {path: path.read_bytes() for path in before} == before


@pytest.mark.parametrize("flag", [["--learning-rate", "nan"], ["--guidance", "1e39"], ["--checkpoint-interval", "100"]])
def test_invalid_arguments_are_refused_before_touching_the_disk(flag, tmp_path):
    line = one_line_error(run_script("discrete", "--output-dir", str(tmp_path / "runs"), *flag))
    assert flag[0] in line
    assert not (tmp_path / "runs").exists()


def test_finished_and_unfinished_runs_need_an_explicit_choice(tmp_path):
    args = small_args("discrete", tmp_path)
    run_dir = train(ppo_pgg_discrete, args)
    with pytest.raises(ppo_pgg_discrete.RunDirError, match="holds a finished run: pass --overwrite"):
        ppo_pgg_discrete.prepare_run_dir(args)
    ppo_pgg_discrete.checkpoint_path(run_dir, 1536).unlink()
    with pytest.raises(ppo_pgg_discrete.RunDirError, match=r"unfinished run \(last checkpoint step_000001024.pt\): pass --resume"):
        ppo_pgg_discrete.prepare_run_dir(args)
    train(ppo_pgg_discrete, replace(args, overwrite=True, total_timesteps=512, checkpoint_interval=512))
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["step_000000512.pt"]


def test_a_run_directory_in_use_is_refused(tmp_path):
    run_dir = tmp_path / "busy"
    run_dir.mkdir()
    lock = ppo_pgg_discrete.lock_directory(run_dir)
    try:
        line = one_line_error(run_script("discrete", "--output-dir", str(tmp_path), "--run-name", "busy"))
        assert f"{run_dir} is in use by another process (pid {os.getpid()})" in line
    finally:
        lock.close()
    # The lock went with its holder: the directory is free again.
    ppo_pgg_discrete.lock_directory(run_dir).close()


# --- interaction ---------------------------------------------------------------------------------


def test_ctrl_c_exits_130_with_one_line_saying_what_is_kept(tmp_path):
    script = ROOT / "ppo_pgg_discrete.py"
    flags = ["--output-dir", str(tmp_path), "--run-name", "stopped", "--checkpoint-interval", "2048"]
    # A shell without job control starts background jobs with SIGINT ignored, and Python then never
    # raises KeyboardInterrupt: this test (run from such a job) would wait in vain. Ctrl-C's default.
    proc = subprocess.Popen([sys.executable, str(script), *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # fmt: skip
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


def test_progress_is_a_live_bar_in_a_terminal_and_plain_lines_in_a_log(tmp_path, capsys):
    report = ppo_pgg_discrete.ProgressReport(total_steps=1000, first_step=0, interval=0.0)
    report.update(500, [10.0, 20.0])
    report.close()
    line = capsys.readouterr().out.strip()
    assert line.startswith("500/1,000 steps") and "return(last 20) 15.0" in line and "ETA" in line

    flags = ["--output-dir", str(tmp_path), "--total-timesteps", "4096", "--checkpoint-interval", "4096"]
    command = [sys.executable, str(ROOT / "ppo_pgg_discrete.py"), *flags]
    controller, terminal = pty.openpty()
    proc = subprocess.Popen(command, stdin=terminal, stdout=terminal, stderr=terminal, env=dict(os.environ, COLUMNS="250"))
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


def test_capture_video_records_the_first_sub_envs_episodes(tmp_path):
    pytest.importorskip("moviepy", reason="--capture-video needs the [video] extra")
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    import imageio.v3 as iio
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    args = ppo_pgg_discrete.Args(output_dir=str(tmp_path), total_timesteps=512, checkpoint_interval=512, num_envs=1,
                                 num_steps=512, capture_video=True)  # fmt: skip
    assert ppo_pgg_discrete.check_args(args) is None
    run_dir = train(ppo_pgg_discrete, args)
    first = run_dir / "videos" / "rl-video-episode-0.mp4"
    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    length = int(events.Scalars("charts/episodic_length")[0].value)
    assert first.stat().st_size > 0
    assert sum(1 for _ in iio.imiter(first)) == length + 1  # the reset frame and one per step


def test_capture_video_without_a_renderer_is_one_line(tmp_path):
    proc = run_script(
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
    policy = module.RolloutPolicy(agent, 1.1)
    noise = module.gumbel_noise(256, action_dim) if kind == "discrete" else np.random.default_rng(0).standard_normal((256, action_dim))
    actions, logprobs, _ = policy.act(buf.obs[:, 0].numpy(), noise)
    buf.actions[:, 0] = torch.as_tensor(actions)
    buf.logprobs[:, 0] = torch.as_tensor(logprobs)
    args = module.Args(guidance=1.1, cond_dropout=0.3, num_minibatches=1)
    batch = {"obs": buf.obs[:, 0], "actions": buf.actions[:, 0], "logprobs": buf.logprobs[:, 0],
             "advantages": torch.randn(256), "returns": torch.randn(256), "values": torch.zeros(256)}  # fmt: skip
    drop_mask = torch.rand(256) < args.cond_dropout
    _, stats = module.minibatch_loss(agent, batch, torch.arange(256), drop_mask, args)
    assert abs(stats["losses/approx_kl"].item()) < 1e-6 and abs(stats["losses/old_approx_kl"].item()) < 1e-5
    assert stats["losses/clipfrac"].item() == 0.0
    assert stats["pgg/dropped_abs_logratio"].item() > 0.05 and stats["pgg/dropped_fraction"].item() == drop_mask.float().mean()
