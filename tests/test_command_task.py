"""The command task of "Beyond the paper" (paper_study/cheetah_velocity/) and the tool that measures how closely
agents follow its command (beyond/command_tracking.py)."""

import csv
import subprocess
import sys
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT, SCRIPTS, one_line_error, run_main, run_script, small_args, train

import reproduce
from beyond import command_tracking
from paper_study import cheetah_velocity, paper
from paper_study.cheetah_velocity import COMMAND_INDEX, COMMAND_RANGE, ENV_ID
from pgg_utils import checkpoints, checks, scripts

ACTIONS = np.random.default_rng(0).uniform(-1, 1, size=(30, 6))


def test_the_task_is_halfcheetah_v4_with_the_command_appended_and_a_reward_that_tracks_it():
    """Same physics, start states and control cost as HalfCheetah-v4; the observation gains the command at
    COMMAND_INDEX; the reward is v_cmd - |v - v_cmd| - 0.1·Σa² with v HalfCheetah-v4's forward velocity. Fails where
    the physics, the observation's layout, the reward's sign or its terms change."""
    env, reference = gym.make(ENV_ID), gym.make("HalfCheetah-v4")
    assert env.observation_space.shape == (COMMAND_INDEX + 1,) == (18,)
    assert env.action_space == reference.action_space and env.spec.max_episode_steps == 1000
    obs, _ = env.reset(seed=7, options={"command": 1.3})
    ref_obs, _ = reference.reset(seed=7)
    np.testing.assert_array_equal(obs[:COMMAND_INDEX], ref_obs)
    assert obs[COMMAND_INDEX] == 1.3
    for action in ACTIONS:
        obs, reward, terminated, truncated, info = env.step(action)
        ref_obs, ref_reward, *_, ref_info = reference.step(action)
        np.testing.assert_array_equal(obs[:COMMAND_INDEX], ref_obs)
        assert obs[COMMAND_INDEX] == info["command"] == 1.3 and not (terminated or truncated)
        assert info["x_velocity"] == ref_info["x_velocity"]
        expected = 1.3 - abs(ref_info["x_velocity"] - 1.3) - 0.1 * float(np.sum(np.square(action)))
        assert reward == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert ref_reward == pytest.approx(ref_info["x_velocity"] - 0.1 * float(np.sum(np.square(action))))


def test_commands_are_drawn_from_the_training_range_by_the_reset_seed_and_can_be_given():
    """A seed gives one command, in COMMAND_RANGE, the same every time; seeds give different ones; a command given
    at reset replaces the draw but not the start state or the RNG's state after it (common random numbers)."""
    env = gym.make(ENV_ID)
    drawn = [env.reset(seed=s)[0][COMMAND_INDEX] for s in range(200)]
    assert all(COMMAND_RANGE[0] <= c <= COMMAND_RANGE[1] for c in drawn)
    assert len(set(drawn)) == 200 and max(drawn) - min(drawn) > 0.9 * (COMMAND_RANGE[1] - COMMAND_RANGE[0])
    assert [env.reset(seed=s)[0][COMMAND_INDEX] for s in range(5)] == drawn[:5]
    given, _ = env.reset(seed=3, options={"command": -0.5})
    rng_after_given = env.unwrapped.np_random.bit_generator.state
    free, _ = env.reset(seed=3)
    assert given[COMMAND_INDEX] == -0.5 and free[COMMAND_INDEX] == drawn[3]
    np.testing.assert_array_equal(given[:COMMAND_INDEX], free[:COMMAND_INDEX])
    assert env.unwrapped.np_random.bit_generator.state == rng_after_given
    with pytest.raises(ValueError, match="finite number"):
        env.reset(seed=0, options={"command": float("nan")})


def test_one_seed_replays_the_same_episode():
    """Seeding determinism: two copies reset with one seed and stepped with the same actions agree to the bit."""
    trajectories = []
    for _ in range(2):
        env = gym.make(ENV_ID)
        steps = [env.reset(seed=11)[0]]
        steps += [np.append(env.step(a)[0], env.step(a)[1]) for a in ACTIONS[:10]]
        trajectories.append(np.concatenate(steps))
    np.testing.assert_array_equal(*trajectories)


@pytest.mark.slow
def test_the_module_id_registers_the_task_and_training_imports_none_of_the_paper_study():
    """`gym.make` of the module-qualified id imports the module, which registers the task with its time limit and
    render modes; the training script and pgg_utils import nothing of paper_study (the task is a user's own)."""
    code = (
        "import sys, gymnasium as gym, ppo_pgg_continuous, eval_gamma_sweep, pgg_utils.runs\n"
        "assert not [m for m in sys.modules if m.startswith('paper_study')], 'training imported paper_study'\n"
        f"env = gym.make({ENV_ID!r}, render_mode='rgb_array')\n"
        "assert env.spec.max_episode_steps == 1000 and env.render_mode == 'rgb_array'\n"
        "print(type(env.unwrapped).__module__)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "paper_study.cheetah_velocity"


def test_the_command_null_variant_nulls_the_command_index_and_training_checks_it():
    """The set's command-null variant puts the null on COMMAND_INDEX, which training accepts for this task; one past
    the observation is refused in one line."""
    flags = paper.variant_flags(reproduce.grid_variants()["pgg_g1.1_null17"], ENV_ID)
    assert reproduce.variant_name(tuple(flags), ENV_ID, "continuous") == "pgg_g1.1_null17"
    assert flags[flags.index("--null-dims") + 1 :] == [str(COMMAND_INDEX)]
    assert checks.env_error(ENV_ID, "continuous", null_dims=(COMMAND_INDEX,)) is None
    assert "0..17" in checks.env_error(ENV_ID, "continuous", null_dims=(COMMAND_INDEX + 1,))


@pytest.fixture(scope="module")
def command_run(tmp_path_factory):
    """A tiny PGG run of the command task with the null on the command, trained in this process."""
    tmp_path = tmp_path_factory.mktemp("command")
    args = small_args("continuous", tmp_path, env_id=ENV_ID, null_dims=(COMMAND_INDEX,), cond_dropout=0.0)
    return train(SCRIPTS["continuous"], replace(args, total_timesteps=256, checkpoint_interval=256))


def tracking_args(tmp_path, paths, **overrides) -> command_tracking.Args:
    settings = {"gammas": (1.0, 2.0), "commands": (0.5, 3.0), "episodes": 2, "output": str(tmp_path / "t.csv")}
    return command_tracking.Args(paths=tuple(map(str, paths)), **{**settings, **overrides})


@pytest.mark.slow
def test_tracking_replays_each_episode_as_the_agent_acts_alone(command_run, tmp_path):
    """Each row is the episode the agent plays on its own (reset seed eval_seed + k with the command, the sweep's
    noise for episode k, one observation per `act`): its command, mean velocity (displacement over duration),
    errors and return; the training range is flagged; a rerun reads the checkpoint's part instead of playing.
    Episode 0 sits in the first row of every forward, alone or in a cell, so its replay is exact (fast.py)."""
    checkpoint = checkpoints.checkpoints_of(command_run)[-1]
    args = tracking_args(tmp_path, [checkpoint])
    rows, skipped = command_tracking.evaluate_checkpoint(checkpoint, args)
    assert skipped is None and len(rows) == 2 * 2 * 2
    agent, _ = scripts.load_checkpoint(checkpoint)
    assert {r["variant"] for r in rows} == {"pgg_g1.1_null17"}
    for row in (r for r in rows if r["episode"] == 0):
        env = gym.make(ENV_ID)
        k, gamma, command = row["episode"], row["eval_guidance"], row["command"]
        noise = command_tracking.evaluation.episode_noise("continuous", args.eval_seed, k, 1000, 6)
        obs, _ = env.reset(seed=args.eval_seed + k, options={"command": command})
        x0, total, velocities = env.unwrapped.data.qpos[0], 0.0, []
        for t in range(1000):
            obs, reward, _, _, info = env.step(agent.act(obs, guidance=gamma, noise=noise[t]))
            total, velocities = total + reward, velocities + [info["x_velocity"]]
        displacement = (env.unwrapped.data.qpos[0] - x0) / (1000 * env.unwrapped.dt)
        assert row["mean_velocity"] == pytest.approx(displacement, rel=1e-9)
        assert row["return"] == total
        assert row["velocity_error"] == pytest.approx(row["mean_velocity"] - command)
        assert row["tracking_error"] == pytest.approx(np.mean(np.abs(np.array(velocities) - command)), rel=1e-12)
        assert row["in_training_range"] == ("yes" if command == 0.5 else "no")
    part = next((tmp_path / "t.csv.parts").iterdir())
    part.write_text(part.read_text().replace(",yes,", ",YES,"))  # a rerun reads the part: the mark shows it
    again, _ = command_tracking.evaluate_checkpoint(checkpoint, args)
    assert {r["in_training_range"] for r in again} == {"YES", "no"}


def test_tracking_skips_another_tasks_checkpoint_and_refuses_bad_settings_in_one_line(tmp_path):
    """A checkpoint of another task is named and left out (no rows); with nothing left, an error line, exit 2, no
    file; a repeated γ or a zero episode count is one line, exit 2."""
    other = train(
        SCRIPTS["continuous"], small_args("continuous", tmp_path, total_timesteps=256, checkpoint_interval=256)
    )
    checkpoint = checkpoints.checkpoints_of(other)[-1]
    rows, skipped = command_tracking.evaluate_checkpoint(checkpoint, tracking_args(tmp_path, [checkpoint]))
    assert rows == [] and "Humanoid-v4 is not the command task" in skipped
    tool = command_tracking  # its main in this process (test_the_cli_writes_every_episode_sorted runs the command)
    proc = run_main(tool, str(other), "--output", str(tmp_path / "x.csv"), "--episodes", "1")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and not (tmp_path / "x.csv").exists()
    assert "not the command task" in proc.stderr and "error: no checkpoint of the command task" in proc.stderr
    for flags, message in ((["--gammas", "1", "1"], "--gammas needs distinct"), (["--episodes", "0"], "positive")):
        proc = run_main(tool, str(other), "--output", str(tmp_path / "x.csv"), *flags)
        assert message in one_line_error(proc)


@pytest.mark.slow
def test_the_cli_writes_every_episode_sorted(command_run, tmp_path):
    """The command writes one row per episode of every cell, with the CSV's columns, in a stable order."""
    proc = run_script("beyond/command_tracking.py", str(command_run), "--output", str(tmp_path / "t.csv"),
                      "--gammas", "1", "--commands", "0", "2.5", "--episodes", "2")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    with open(tmp_path / "t.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert reader.fieldnames == command_tracking.COLUMNS and len(rows) == 2 * 2
    assert [(r["command"], r["episode"]) for r in rows] == [("0.0", "0"), ("0.0", "1"), ("2.5", "0"), ("2.5", "1")]
    assert cheetah_velocity.__file__.endswith("cheetah_velocity/__init__.py") and rows[0]["task_sha1"]


def test_the_launcher_sweeps_what_the_issue_asks_and_its_grid_passes_the_launchers_checks():
    """results/beyond/command/run_all.sh: at least 5 γ with one below 1 and one above 1.5, commands inside and outside
    the training range, 50 episodes, the three variants; reproduce.py accepts its grid before training anything."""
    import re

    import reproduce

    script = (ROOT / "results" / "beyond" / "command" / "run_all.sh").read_text()
    gammas = [float(g) for g in re.search(r"^GAMMAS=\(([^)]*)\)", script, re.MULTILINE).group(1).split()]
    commands = [float(c) for c in re.search(r"^COMMANDS=\(([^)]*)\)", script, re.MULTILINE).group(1).split()]
    assert len(gammas) >= 5 and min(gammas) < 1 and max(gammas) > 1.5 and 1.0 in gammas
    low, high = COMMAND_RANGE
    assert (
        any(low <= c <= high for c in commands) and any(c > high for c in commands) and any(c < low for c in commands)
    )
    assert "--episodes 50" in script and f"env={ENV_ID}" in script
    variants = ("ppo", "pgg_g1.1_null17", "pgg_g1.1")
    assert f"--variants {' '.join(variants)}" in script
    args = reproduce.Args(preset="continuous", envs=(ENV_ID,), variants=variants, gammas=tuple(gammas), workers=2)
    assert reproduce.argument_error(args) is None
