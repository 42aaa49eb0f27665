"""One episode loop: the sweep's `evaluate_cell` plays every evaluation episode, the sweep's cells, --video, the
goal distances, the command tracking and the behaviour-cloned null's own episodes, so an edit to it reaches them
all, and going through it changed none of their numbers."""

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch
from test_sweep_code import FIXTURE, LOOP_LINE, sweep_args, sweep_copy

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from beyond import command_tracking, goal_distance
from paper_study.cheetah_velocity import ENV_ID as COMMAND_ENV_ID
from pgg_utils import bc_null, evaluation, files, tasks


@pytest.mark.slow
def test_the_video_of_a_sweep_copy_films_its_own_cell_episode_with_its_return(tmp_path, capsys):
    """Issue 56, silent 4: a copy of the sweep that transforms the observation in evaluate_cell gives episode 1 a
    return; its --video-episode 1 films that episode and prints that return (it filmed the original's episode,
    through a loop of its own)."""
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    mirrored = sweep_copy(
        tmp_path, "mirrored_sweep", LOOP_LINE, LOOP_LINE.replace("policy.act(obs,", "policy.act(-obs,")
    )
    args = sweep_args(tmp_path / "out", gammas=(1.0,), episodes=3)
    swept = files.read_csv(mirrored.sweep(args) / "episodes.csv")
    original = files.read_csv(sweep.sweep(replace(args, output=str(tmp_path / "original"))) / "episodes.csv")
    assert swept[1]["return"] != original[1]["return"]  # the copy's episodes are its own
    capsys.readouterr()
    mirrored.record_videos(replace(args, video=str(tmp_path / "videos"), video_episode=1))
    printed = capsys.readouterr().err
    assert f"γ = 1: episode 1, return {swept[1]['return']} over {swept[1]['length']} steps" in printed, printed
    assert (tmp_path / "videos" / "gamma_1.mp4").is_file()


def test_a_video_episode_outside_the_cell_is_refused_in_one_line(tmp_path):
    with pytest.raises(files.InputError, match="--video-episode 3 is not an episode of a cell of --episodes 3"):
        sweep.check_args(sweep_args(tmp_path, episodes=3, video=str(tmp_path / "v"), video_episode=3))


def reacher_agent():
    torch.manual_seed(0)
    agent = ppo_pgg_continuous.Agent(11, 2, null_dims=(4, 5, 8, 9, 10), action_bounds=(-np.ones(2), np.ones(2)))
    return agent, {"env_id": "Reacher-v4", "action_space": "continuous", "obs_dim": 11, "action_dim": 2}


def command_agent():
    torch.manual_seed(1)
    env = gym.make(COMMAND_ENV_ID)
    ckpt = {"env_id": COMMAND_ENV_ID, "action_space": "continuous", "action_dim": 6,
            "task_spaces": tasks.describe(env.observation_space, env.action_space)}  # fmt: skip
    bounds = (env.action_space.low, env.action_space.high)
    return ppo_pgg_continuous.Agent(18, 6, null_dims=(17,), action_bounds=bounds), ckpt


def cloning_agent(kind: str):
    torch.manual_seed(2)
    if kind == "discrete":
        return ppo_pgg_discrete.Agent(4, 2), {"env_id": "CartPole-v1", "action_space": "discrete", "n_actions": 2}
    env = gym.make("Hopper-v4")
    ckpt = {"env_id": "Hopper-v4", "action_space": "continuous", "action_dim": 3,
            "task_spaces": tasks.describe(env.observation_space, env.action_space)}  # fmt: skip
    return ppo_pgg_continuous.Agent(11, 3, action_bounds=(env.action_space.low, env.action_space.high)), ckpt


def test_goal_distance_tracking_and_cloning_play_their_episodes_through_the_sweeps_loop(monkeypatch):
    """Fails where one of them plays its episodes with a loop of its own: an edit to the sweep's loop (an
    observation transform, a fix) would not reach it."""
    played, real_cell = [], evaluation.evaluate_cell
    monkeypatch.setattr(evaluation, "evaluate_cell", lambda *a, **k: played.append(a[2]) or real_cell(*a, **k))
    agent, ckpt = reacher_agent()
    goal_distance.final_distances(evaluation.GuidedPolicy(agent, ckpt), ckpt, 1.5, 2, 10_000)
    agent, ckpt = command_agent()
    policy = evaluation.GuidedPolicy(agent, ckpt, module=ppo_pgg_continuous)
    command_tracking.play_cell(policy, ckpt, 2.0, 0.5, 1, 30_000)
    agent, ckpt = cloning_agent("discrete")
    bc_null.own_episodes(agent, ckpt, ppo_pgg_discrete.make_env("CartPole-v1"), 2, 30_000)
    assert played == [1.5, 2.0, 1.0]


# The loops that goal_distance.py, command_tracking.py and bc_null.py played before they used the sweep's, as they
# were written (at b37a440): the references that going through the sweep's loop changed no number.


def goal_distance_before(policy, ckpt, gamma, episodes, eval_seed):
    env = policy.make_env()
    horizon, action_size = evaluation.horizon_and_action_size(env, ckpt)
    out = []
    for k in range(episodes):
        noise = evaluation.episode_noise("continuous", eval_seed, k, horizon, action_size)
        obs, _ = env.reset(seed=eval_seed + k)
        total, t, done = 0.0, 0, False
        while not done:
            action = policy.act(obs[None], np.array([gamma]), noise[t : t + 1], False)[0]
            obs, reward, terminated, truncated, _ = env.step(action)
            total, t, done = total + float(reward), t + 1, terminated or truncated
        out.append((total, goal_distance.FINAL_DISTANCE[ckpt["env_id"]](obs)))
    return out


def tracking_before(agent, make_env, gamma, command, episodes, eval_seed):
    envs = [make_env() for _ in range(episodes)]
    horizon, action_size = envs[0].spec.max_episode_steps, envs[0].action_space.shape[0]
    noise = np.stack([evaluation.episode_noise("continuous", eval_seed, k, horizon, action_size) for k in range(episodes)],
                     axis=1)  # fmt: skip
    obs = np.stack([env.reset(seed=eval_seed + k, options={"command": command})[0] for k, env in enumerate(envs)])
    guidance = np.full(episodes, float(gamma))
    returns, lengths = np.zeros(episodes), np.zeros(episodes, dtype=np.int64)
    velocity_sum, error_sum = np.zeros(episodes), np.zeros(episodes)
    running, t = np.ones(episodes, dtype=bool), 0
    while running.any():
        actions = agent.act(obs, guidance=guidance, noise=noise[t])
        for i in np.flatnonzero(running):
            obs[i], reward, terminated, truncated, info = envs[i].step(actions[i])
            returns[i] += reward
            lengths[i] += 1
            velocity_sum[i] += info["x_velocity"]
            error_sum[i] += abs(info["x_velocity"] - command)
            running[i] = not (terminated or truncated)
        t += 1
    mean_velocity = velocity_sum / lengths
    return [(returns[k], int(lengths[k]), mean_velocity[k], mean_velocity[k] - command, error_sum[k] / lengths[k])
            for k in range(episodes)]  # fmt: skip


def own_episodes_before(agent, ckpt, make_env, episodes, episode_seed):
    envs = [make_env() for _ in range(episodes)]
    rngs = [np.random.default_rng([episode_seed + k, 2]) for k in range(episodes)]
    obs = np.stack([env.reset(seed=episode_seed + k)[0] for k, env in enumerate(envs)])
    running, seen_actions = np.ones(episodes, dtype=bool), []
    with torch.no_grad():
        while running.any():
            rows = np.flatnonzero(running)
            if ckpt["action_space"] == "discrete":
                logits = agent.acting_policy(obs[rows].astype(np.float32), 1.0).logits
                gumbel = np.stack([rngs[i].gumbel(size=logits.shape[-1]) for i in rows])
                actions = (logits + gumbel).argmax(-1)
                env_actions = actions
            else:
                policy = agent.acting_policy(obs[rows], 1.0)
                noise = np.stack([rngs[i].standard_normal(policy.mode().shape[-1]) for i in rows])
                actions = policy.sample(noise)
                env_actions = np.clip(actions, *agent.action_bounds) if agent.action_bounds is not None else actions
            seen_actions.append(actions)
            for j, i in enumerate(rows):
                obs[i], _, terminated, truncated, _ = envs[i].step(env_actions[j])
                running[i] = not (terminated or truncated)
    return np.concatenate(seen_actions)


def test_going_through_the_sweeps_loop_changed_no_number():
    """Each tool against its own loop as it was, to the last bit, on a small case of each: episodes of different
    lengths (the cloned Hopper's), the command as a reset option, unclipped continuous samples and Gumbel-max
    discrete ones. (On the committed agents: benchmarks/compare_revisions.py, which runs each tool at two
    revisions.) Every forward here has the same row count in both loops, cell_rows(1) = cell_rows(5) = 8, and a
    row's result depends on its own values and the row count (fast.evaluation_forward)."""
    agent, ckpt = reacher_agent()
    policy = evaluation.GuidedPolicy(agent, ckpt)
    assert goal_distance.final_distances(policy, ckpt, 1.5, 3, 10_000) == goal_distance_before(
        policy, ckpt, 1.5, 3, 10_000
    )

    agent, ckpt = command_agent()
    policy = evaluation.GuidedPolicy(agent, ckpt, module=ppo_pgg_continuous)
    rows = command_tracking.play_cell(policy, ckpt, 2.0, 3.0, 2, 30_000)
    columns = ("return", "length", "mean_velocity", "velocity_error", "tracking_error")
    assert [tuple(row[c] for c in columns) for row in rows] == tracking_before(
        agent, ppo_pgg_continuous.make_env(COMMAND_ENV_ID), 2.0, 3.0, 2, 30_000
    )

    for kind, module in (("discrete", ppo_pgg_discrete), ("continuous", ppo_pgg_continuous)):
        agent, ckpt = cloning_agent(kind)
        make_env = module.make_env(ckpt["env_id"])
        actions = bc_null.own_episodes(agent, ckpt, make_env, 5, 30_000)
        before = own_episodes_before(agent, ckpt, make_env, 5, 30_000)
        assert actions.dtype == before.dtype and np.array_equal(actions, before), kind
    assert len(before) > 5 * 10  # several steps an episode, some episodes ending before others


def test_the_fixture_sweep_is_unchanged_by_the_hooks():
    """The sweep's cells with hooks that only watch are the cells without them."""

    class Watching(evaluation.EpisodeHooks):
        steps = 0

        def after_step(self, episode, t, obs, reward, done, info):
            self.steps += 1

    agent, ckpt = evaluation.load_any_checkpoint(FIXTURE)
    policy, watching = evaluation.GuidedPolicy(agent, ckpt), Watching()
    watched = evaluation.evaluate_cell(policy, ckpt, 2.0, 4, 10_000, False, watching)
    plain = evaluation.evaluate_cell(policy, ckpt, 2.0, 4, 10_000, False)
    assert all(np.array_equal(watched[c], plain[c]) for c in plain) and watching.steps == plain["length"].sum()
