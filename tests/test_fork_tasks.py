"""The task is what `make_env` makes, and the return reported is the task's own: a fork's wrapper in make_env (an
action rescale, a flattened action space, a reward scale) trains and is swept on the task it makes, and a vector env
that cannot checkpoint, resume or report the task's return stops before training in one line."""

import dataclasses
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT, small_args

import eval_gamma_sweep as sweep
from pgg_utils import checkpoints, files, runs, scripts

# Pendulum as a tiny continuous run: four checkpoints' worth of Humanoid would take minutes.
PENDULUM = {"env_id": "Pendulum-v1", "total_timesteps": 768, "checkpoint_interval": 768, "num_steps": 256,
            "num_minibatches": 4, "update_epochs": 2}  # fmt: skip


def write_fork(folder: Path, original: str, addition: str, name: str | None = None, edits: dict | None = None) -> Path:
    """A copy of a training script with `addition` (code that redefines make_env, or defines a vector env) before
    its `if __name__ == "__main__":`, and `edits` (old text: new) made, as a fork edits it; imported as its own
    module."""
    source = (ROOT / original).read_text()
    for old, new in (edits or {}).items():
        assert source.count(old) == 1
        source = source.replace(old, new)
    main = 'if __name__ == "__main__":\n'
    assert source.count(main) == 1
    path = folder / (name or f"fork_{original}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(source.replace(main, addition + "\n\n" + main))
    return path


def train_fork(path: Path, tmp_path, kind: str, **overrides) -> Path:
    """Trains a tiny run with the fork at `path`, in this process; returns its run directory."""
    module = scripts.load_module(path)
    base = dataclasses.asdict(small_args(kind, tmp_path / "runs", **overrides))
    return runs.train_in_process(module, module.Args(**base))


def swept(tmp_path, output: str, *given: Path) -> list[dict]:
    """The sweep's episodes of every run under tmp_path/runs, at γ 1 and 2, evaluated by `given` (--script)."""
    args = sweep.Args(paths=(str(tmp_path / "runs"),), output=str(tmp_path / output), gammas=(1.0, 2.0), episodes=2,
                      script=tuple(map(str, given)))  # fmt: skip
    sweep.sweep(args)
    return files.read_csv(tmp_path / output / "episodes.csv")


def logged(run_dir, tag: str) -> list[float]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    return [e.value for e in events.Scalars(tag)]


# --- the task's contract is make_env's ------------------------------------------------------------------------------

RESCALED_ACTIONS = '''
original_make_env = make_env


def make_env(env_id: str, video_dir=None, render_mode=None):
    """The original's task, its actions rescaled to [-1, 1]."""
    made = original_make_env(env_id, video_dir, render_mode)
    return lambda: gym.wrappers.RescaleAction(made(), -1.0, 1.0)
'''


def test_an_action_rescale_in_make_env_is_the_task_the_checkpoint_records_and_the_sweep_evaluates(tmp_path):
    """RescaleAction on make_env's env: the checkpoint records [-1, 1], the bounds the agent acts in, so the sweep
    evaluates it (today's main recorded the bare task's [-2, 2] and refused: "action low [-2.0] in training, [-1.0]
    now")."""
    fork = write_fork(tmp_path / "fork", "ppo_pgg_continuous.py", RESCALED_ACTIONS)
    run_dir = train_fork(fork, tmp_path, "continuous", **PENDULUM)
    ckpt = torch.load(checkpoints.checkpoints_of(run_dir)[-1], weights_only=True)
    assert ckpt["task_spaces"]["action"]["low"] == [-1.0] and ckpt["task_spaces"]["action"]["high"] == [1.0]
    assert (ckpt["action_low"], ckpt["action_high"]) == ([-1.0], [1.0])
    rows = swept(tmp_path, "sweep", fork)
    assert len(rows) == 4 and not files.read_csv(tmp_path / "sweep" / "skipped.csv")
    agent = scripts.load_module(fork).load_checkpoint(checkpoints.checkpoints_of(run_dir)[-1])[0]
    low, high = agent.action_bounds
    assert low.tolist() == [-1.0] and high.tolist() == [1.0]  # `act` clips to the task it acts in


GRID_TASK = """
import gymnasium as gym
import numpy as np


class Grid(gym.Env):
    \"\"\"Two joint choices a step; a reward for each right one.\"\"\"

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gym.spaces.MultiDiscrete([2, 3])

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        return self.np_random.normal(size=2).astype(np.float32), {}

    def step(self, action):
        reward = float(action[0] == 1) + float(action[1] == 2)
        return self.np_random.normal(size=2).astype(np.float32), reward, False, False, {}


gym.register("ForkGrid-v0", entry_point=Grid, max_episode_steps=10)
"""

FLATTENED_ACTIONS = '''
class FlatActions(gym.ActionWrapper):
    """A MultiDiscrete action space as one Discrete: action k is the k-th combination."""

    def __init__(self, env):
        super().__init__(env)
        self.nvec = env.action_space.nvec
        self.action_space = gym.spaces.Discrete(int(np.prod(self.nvec)))

    def action(self, action):
        return np.array(np.unravel_index(int(action), self.nvec))


original_make_env = make_env


def make_env(env_id: str, video_dir=None, render_mode=None):
    made = original_make_env(env_id, video_dir, render_mode)
    return lambda: FlatActions(made())
'''


def test_a_multidiscrete_task_flattened_in_make_env_trains_and_is_swept(tmp_path, monkeypatch, capsys):
    """The space checks read the env make_env makes: a MultiDiscrete task that make_env flattens to Discrete trains
    (today's main refused it, reading gym.make's env: "MultiDiscrete action space; neither script trains it")."""
    (tmp_path / "tasks").mkdir()
    (tmp_path / "tasks" / "fork_grid_task.py").write_text(GRID_TASK)
    monkeypatch.syspath_prepend(str(tmp_path / "tasks"))
    fork = write_fork(tmp_path / "fork", "ppo_pgg_discrete.py", FLATTENED_ACTIONS)
    module = scripts.load_module(fork)
    args = module.Args(
        **dataclasses.asdict(small_args("discrete", tmp_path / "runs", env_id="fork_grid_task:ForkGrid-v0"))
    )
    runs.launch(args, module.ACTION_SPACE, str(fork), module.train)  # the checks a command line passes, then training
    (ckpt,) = [torch.load(path, weights_only=True) for path in (tmp_path / "runs").glob("*/checkpoints/*1536.pt")]
    assert ckpt["task_spaces"]["action"] == {"type": "Discrete", "n": 6, "start": 0}
    rows = swept(tmp_path, "sweep", fork)
    assert len(rows) == 12 and all(0 <= float(row["return"]) <= 20 for row in rows)  # 3 checkpoints, 2 γ, 2 episodes
    # The unflattened task is still refused by the original script, in one line.
    original = scripts.load_module(ROOT / "ppo_pgg_discrete.py")
    with pytest.raises(SystemExit):
        runs.launch(dataclasses.replace(args, run_name="original"), "discrete", str(ROOT / "ppo_pgg_discrete.py"),
                    original.train)  # fmt: skip
    assert "MultiDiscrete action space" in capsys.readouterr().err.strip().splitlines()[-1]


# --- vector envs: train, checkpoint, resume and sweep, or stop before training --------------------------------------

ASYNC = "gym.vector.AsyncVectorEnv([make_env(env_id) for _ in range(num_envs)], autoreset_mode=SAME_STEP)"
MADE_VECTOR = 'gym.make_vec(env_id, num_envs, "sync", vector_kwargs={"autoreset_mode": SAME_STEP})'
VECTOR_ENVS = {
    "async": (ASYNC, "make_vector_env returns AsyncVectorEnv: a checkpoint holds each sub-env's state"),
    "make_vec_recorded": (f"gym.wrappers.vector.RecordEpisodeStatistics({MADE_VECTOR})",
                          "make_vector_env returns its vector env wrapped in RecordEpisodeStatistics"),
    "make_vec": (MADE_VECTOR, "make_vector_env's sub-envs do not report the task's own return"),
    "next_step": ("gym.vector.SyncVectorEnv([make_env(env_id) for _ in range(num_envs)])",
                  "make_vector_env's SyncVectorEnv resets a finished sub-env with autoreset mode"),
}  # fmt: skip
VECTOR_FORK = """
SAME_STEP = gym.vector.AutoresetMode.SAME_STEP


def make_vector_env(env_id: str, num_envs: int, seed: int, video_dir=None):
    envs = {vector_env}
    envs.action_space.seed(seed)
    return envs
"""


@pytest.mark.parametrize("vector_env", VECTOR_ENVS, ids=VECTOR_ENVS)
def test_a_vector_env_that_cannot_checkpoint_resume_or_report_the_tasks_return_stops_before_training(
    vector_env, tmp_path, capsys
):
    """CleanRL users' vector envs: AsyncVectorEnv (today: AttributeError 'envs' at the first checkpoint), gym.make_vec
    with or without the vector RecordEpisodeStatistics (today: KeyError '_episode'), and a SyncVectorEnv that resets a
    finished sub-env at its next step (today: trains with GAE across episodes and logs no episode) stop in one line
    that says what to do, before a step is taken or anything but args.json is written."""
    code, message = VECTOR_ENVS[vector_env]
    own_vector_env = {"tasks.make_vector_env(make_env, ": "make_vector_env("}  # train builds the fork's
    fork = write_fork(
        tmp_path / "fork", "ppo_pgg_discrete.py", VECTOR_FORK.format(vector_env=code), edits=own_vector_env
    )
    with pytest.raises(SystemExit) as stopped:
        train_fork(fork, tmp_path, "discrete", run_name="refused")
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert stopped.value.code == 2 and line.startswith(f"error: {message}")
    assert sorted(path.name for path in (tmp_path / "runs" / "refused").iterdir()) == [".lock", "args.json"]


# --- the reported return is the task's own ---------------------------------------------------------------------------

REWARD_SCALE = "env = gym.wrappers.TransformReward(env, lambda reward: 0.1 * reward)"


def with_reward_scale(original: str, folder: Path) -> Path:
    """A fork whose make_env scales the reward as the first wrapper it puts on its env, the nearest to the task that
    make_env reaches (on today's main, the line after gym.make, under RecordEpisodeStatistics)."""
    source = (ROOT / original).read_text()
    start = source.index("def make_env(")
    line_start = source.index("        env = ", start)
    line_end = source.index("\n", line_start) + 1
    path = folder / original
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(source[:line_end] + f"        {REWARD_SCALE}\n" + source[line_end:])
    return path


def test_a_reward_scale_anywhere_in_make_env_trains_the_agent_but_never_changes_the_reported_return(tmp_path):
    """CartPole pays 1 a step: with the reward scaled by 0.1 in make_env, the agent's env pays 0.1, while training's
    logged returns and the sweep's are the episodes' lengths (today's main reported 4.7 for a 47-step episode)."""
    fork = with_reward_scale("ppo_pgg_discrete.py", tmp_path / "fork")
    env = scripts.load_module(fork).make_env("CartPole-v1")()
    env.reset(seed=0)
    assert env.step(0)[1] == pytest.approx(0.1)
    run_dir = train_fork(fork, tmp_path, "discrete")
    returns, lengths = logged(run_dir, "charts/episodic_return"), logged(run_dir, "charts/episodic_length")
    assert len(returns) > 10 and returns == lengths
    rows = swept(tmp_path, "sweep", fork)
    assert [float(row["return"]) for row in rows] == [float(row["length"]) for row in rows]


@pytest.mark.slow
def test_a_reward_scale_in_make_env_leaves_a_continuous_tasks_swept_returns_those_of_the_unscaled_script(tmp_path):
    """Pendulum's fractional returns: a checkpoint swept through the fork that scales its reward and through the
    original's make_env (a copy of the same file name) gives the same returns, to the bit."""
    fork = with_reward_scale("ppo_pgg_continuous.py", tmp_path / "fork")
    train_fork(fork, tmp_path, "continuous", **PENDULUM)
    unscaled = tmp_path / "unscaled" / "ppo_pgg_continuous.py"
    unscaled.parent.mkdir()
    unscaled.write_text((ROOT / "ppo_pgg_continuous.py").read_text())
    scaled_rows, unscaled_rows = swept(tmp_path, "scaled", fork), swept(tmp_path, "unscaled", unscaled)
    assert [row["return"] for row in scaled_rows] == [row["return"] for row in unscaled_rows]
    assert all(float(row["return"]) < -100 for row in scaled_rows)  # Pendulum's own scale, not a tenth of it


def test_a_fork_that_means_to_report_a_shaped_return_says_so_in_task_envs_below_record(tmp_path):
    """The one place a shaped return is reported from: a reward wrapper in task_env's `below_record`."""
    source = (ROOT / "ppo_pgg_discrete.py").read_text()
    call = "env = tasks.task_env(env_id, video_dir, render_mode)"
    assert source.count(call) == 1
    shaped = "below_record=(lambda env: gym.wrappers.TransformReward(env, lambda reward: 0.1 * reward),)"
    fork = tmp_path / "fork" / "ppo_pgg_discrete.py"
    fork.parent.mkdir()
    fork.write_text(source.replace(call, call.replace("render_mode)", f"render_mode, {shaped})")))
    run_dir = train_fork(fork, tmp_path, "discrete")
    returns, lengths = logged(run_dir, "charts/episodic_return"), logged(run_dir, "charts/episodic_length")
    np.testing.assert_allclose(returns, 0.1 * np.array(lengths), rtol=1e-5)


def test_every_sub_env_of_the_training_scripts_reports_the_tasks_return_from_beneath_make_envs_wrappers():
    """What the rule rests on: the recorder is directly on gym.make's env (the continuous script's FlattenObservation,
    which changes no reward, beside it), not at the top of make_env."""
    from pgg_utils.tasks import records_task_return

    for script in ("ppo_pgg_discrete.py", "ppo_pgg_continuous.py"):
        env = scripts.load_module(ROOT / script).make_env("Pendulum-v1" if "continuous" in script else "CartPole-v1")()
        assert records_task_return(env)
        while not isinstance(env, gym.wrappers.RecordEpisodeStatistics):
            env = env.env
        assert isinstance(env.env, (gym.wrappers.TimeLimit, gym.wrappers.FlattenObservation))
