import json
import subprocess
import sys
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT, assert_minibatch_loss_is_cleanrls, small_args, train, training_vector_env
from torch.distributions import Normal

import ppo_pgg_continuous as pgg
from paper_study.paper import PAPER_ENVS
from pgg_utils import checkpoints, checks
from pgg_utils.guidance import uses_null_branch
from pgg_utils.tasks import TASK_EPISODE

PAPER_TASKS = PAPER_ENVS["continuous"]


def run(args: pgg.Args):
    return train(pgg, args)


def tiny_args(tmp_path, **overrides) -> pgg.Args:
    """Two checkpoints of PPO on InvertedPendulum, 2 iterations of 512 steps."""
    base = {"env_id": "InvertedPendulum-v4", "total_timesteps": 1024, "num_steps": 512, "num_minibatches": 8, "update_epochs": 2,
                "checkpoint_interval": 512, "guidance": 1.0, "cond_dropout": 0.0}  # fmt: skip
    return small_args("continuous", tmp_path, **{**base, **overrides})


@pytest.mark.parametrize("guidance", [0.0, 0.5, 1.0, 1.1, 1.5, 3.0])
def test_guided_gaussian_is_normalised_product(guidance):
    """N(mu_null, σ)^(1-γ) N(mu_s, σ)^γ, normalised numerically on a grid, equals N(mu_hat, σ)."""
    torch.manual_seed(0)
    agent = pgg.Agent(obs_dim=3, action_dim=1).double()
    with torch.no_grad():
        agent.actor_mean[-1].weight.mul_(100)
        agent.null_obs.normal_()
        agent.actor_logstd.fill_(-0.3)
    obs = torch.randn(4, 3, dtype=torch.float64)
    with torch.no_grad():
        mean_hat = agent.policy(obs, guidance).mean
        mean_cond = agent.actor_mean(obs)
        mean_null = agent.actor_mean(agent.null_obs.unsqueeze(0))
    grid = torch.linspace(-15, 15, 30001, dtype=torch.float64).unsqueeze(-1)  # (G, 1) actions
    logstd = agent.actor_logstd.detach()
    for i in range(4):
        log_unnormalised = (1 - guidance) * pgg.Gaussian(mean_null, logstd).log_prob(grid) + guidance * (
            pgg.Gaussian(mean_cond[i], logstd).log_prob(grid)
        )
        density = log_unnormalised.exp()
        density = density / torch.trapezoid(density, grid.squeeze(-1))
        expected = pgg.Gaussian(mean_hat[i], logstd).log_prob(grid).exp()
        torch.testing.assert_close(density, expected, rtol=1e-6, atol=1e-9)
    if guidance == 1.0:
        assert torch.equal(mean_hat, mean_cond)
    if guidance == 0.0:
        torch.testing.assert_close(mean_hat, mean_null.expand(4, 1), rtol=1e-12, atol=1e-12)


def null_grad(guidance, cond_dropout):
    torch.manual_seed(0)
    agent = pgg.Agent(obs_dim=4, action_dim=2)
    optimizer = torch.optim.Adam(agent.parameters(), lr=1e-3)
    buf = pgg.Rollout.empty(32, 1, 4, 2)
    buf.obs.normal_()
    buf.actions.normal_()
    with torch.no_grad():
        buf.logprobs.copy_(pgg.Gaussian(torch.zeros(2), agent.actor_logstd).log_prob(buf.actions))
    args = pgg.Args(guidance=guidance, cond_dropout=cond_dropout, update_epochs=1, num_minibatches=1)
    guidance = torch.tensor(args.guidance) if uses_null_branch(args) else None  # as train() decides
    pgg.ppo_update(agent, optimizer, buf, torch.randn(32, 1), torch.randn(32, 1), args, guidance)
    return agent.null_obs.grad


def test_null_embedding_gradient_only_when_guidance_differs_from_one_or_dropout():
    assert null_grad(1.0, 0.0) is None
    assert null_grad(1.1, 0.0).abs().sum() > 0
    assert null_grad(1.0, 0.3).abs().sum() > 0


class VanillaAgent(pgg.Agent):
    def __init__(self, obs_dim, action_dim, obs_clip=10.0, null_dims=None, action_bounds=None):
        super().__init__(obs_dim, action_dim, obs_clip, null_dims, action_bounds)
        del self.null_obs

    def unconditional_mean(self):
        return torch.zeros(self.actor_logstd.shape[-1])  # `guide` is patched to return the conditional branch

    def branches(self, obs, drop_mask=None):
        cond = pgg.Gaussian(self.actor_mean(obs), self.actor_logstd)
        return cond, cond  # `guide` is patched to return the conditional branch


def test_guidance_one_is_exactly_vanilla_ppo(tmp_path, monkeypatch):
    args = tiny_args(tmp_path)
    ours = torch.load(checkpoints.checkpoint_path(run(args), 1024), weights_only=True)["model"]
    monkeypatch.setattr(pgg, "Agent", VanillaAgent)
    monkeypatch.setattr(pgg, "guide", lambda cond, null, guidance: cond)
    monkeypatch.setattr(pgg, "guidance_diagnostics", lambda *a: {})
    vanilla = torch.load(checkpoints.checkpoint_path(run(replace(args, run_name="vanilla")), 1024), weights_only=True)[
        "model"
    ]
    assert set(ours) - set(vanilla) == {"null_obs"}
    assert [k for k in vanilla if not torch.equal(ours[k], vanilla[k])] == []


CHECK_IN_FRESH_PROCESS = """
import json, sys, torch
sys.path.insert(0, sys.argv[1])
import ppo_pgg_continuous as pgg
agent, _ = pgg.load_checkpoint(sys.argv[2])
raw = torch.tensor(json.loads(sys.argv[3]), dtype=torch.float64)
before = {k: v.clone() for k, v in agent.obs_norm.state_dict().items()}
with torch.no_grad():
    mean = agent.policy(agent.obs_norm(raw), 1.1).mean
assert all(torch.equal(v, agent.obs_norm.state_dict()[k]) for k, v in before.items())
print(json.dumps(mean.double().tolist()))
"""


@pytest.mark.slow
def test_checkpoint_carries_observation_statistics(tmp_path):
    """A checkpoint alone maps a raw observation to the training-time action mean (cleanrl#425)."""
    run_dir = run(tiny_args(tmp_path, guidance=1.1, env_id="Hopper-v4"))
    agent, ckpt = pgg.load_checkpoint(checkpoints.checkpoint_path(run_dir, 1024))
    assert ckpt["global_step"] == 1024 and ckpt["action_space"] == "continuous" and ckpt["env_id"] == "Hopper-v4"
    assert float(agent.obs_norm.count) > 1000 and agent.obs_norm.mean.abs().sum() > 0
    raw = np.random.default_rng(0).normal(size=(3, 11)) * 2 + 1
    with torch.no_grad():
        in_process = agent.policy(agent.obs_norm(raw), 1.1).mean
        unnormalised = agent.policy(torch.as_tensor(raw, dtype=torch.float32).clamp(-10, 10), 1.1).mean
    assert not torch.allclose(in_process, unnormalised, atol=1e-3)  # the statistics matter
    out = subprocess.run(
        [sys.executable, "-c", CHECK_IN_FRESH_PROCESS, str(ROOT), str(checkpoints.checkpoint_path(run_dir, 1024)),
         json.dumps(raw.tolist())],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert torch.equal(torch.tensor(json.loads(out.stdout)).float(), in_process)


def test_episodes_are_reported_with_raw_returns_at_the_step_they_end():
    """Episode statistics come from each sub-env's wrapper (under infos["final_info"] with same-step
    autoreset), recorded before reward normalisation: InvertedPendulum pays 1 per step. Each episode
    is logged at the global step at which it ended, as CleanRL does; with one sub-env that is the
    running sum of the episode lengths."""
    envs = training_vector_env(pgg, "InvertedPendulum-v4", 1, seed=0)
    obs, _ = envs.reset(seed=0)
    buf = pgg.Rollout.empty(200, 1, 4, 1)
    torch.manual_seed(0)
    policy, episodes = pgg.FastPolicy(pgg.Agent(4, 1), 1.0), []
    _, next_done = pgg.collect_rollout(
        policy, envs, policy.obs_norm.observe(obs), np.zeros(1, np.float32), buf,
        lambda r, l, step: episodes.append((r, l, step)), global_step=4096,
    )  # fmt: skip
    returns, lengths, steps = map(np.array, zip(*episodes))
    assert len(episodes) == int(buf.dones[1:].sum() + next_done.sum()) > 10
    assert (returns == lengths).all()
    assert (steps == 4096 + np.cumsum(lengths)).all()
    # The rollout's rewards are normalised (reward / std of the discounted return) and clipped.
    assert buf.rewards[0].tolist() == [10.0] and buf.rewards[-1].max() < 1.0


def test_observation_statistics_are_cleanrls_across_episode_ends(monkeypatch):
    """The agent's statistics equal those of gymnasium's NormalizeObservation on the sub-env (CleanRL's
    wrapper), stepped with the same actions: every observation a reset or step returns, terminal ones
    included, in the same order. Hopper with a 25-step time limit ends episodes both ways."""
    short = lambda env_id, video_dir=None: (
        lambda: gym.wrappers.RecordEpisodeStatistics(
            gym.wrappers.FlattenObservation(gym.make(env_id, max_episode_steps=25)), stats_key=TASK_EPISODE
        )
    )
    monkeypatch.setattr(pgg, "make_env", short)
    envs = training_vector_env(pgg, "Hopper-v4", 1, seed=3)
    agent = pgg.Agent(11, 3)
    policy = pgg.FastPolicy(agent, 1.0)
    buf = pgg.Rollout.empty(400, 1, 11, 3)
    raw_obs, _ = envs.reset(seed=3)
    _next_obs, _next_done = pgg.collect_rollout(
        policy, envs, policy.obs_norm.observe(raw_obs), np.zeros(1, np.float32), buf, lambda *_: None, 0
    )

    def cleanrl_wrapper():
        wrapper = gym.wrappers.NormalizeObservation(gym.wrappers.ClipAction(short("Hopper-v4")()))
        # gymnasium 1.4 starts its statistics as float32 (the normalised space's dtype), which rounds
        # the first update's var * count; gymnasium 0.29, CleanRL's, keeps them in float64 throughout.
        wrapper.obs_rms = gym.wrappers.utils.RunningMeanStd(shape=(11,))
        return wrapper

    reference = gym.vector.SyncVectorEnv([cleanrl_wrapper], autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    reference.reset(seed=3)
    terminated = truncated = 0
    for action in buf.actions.numpy():
        _, _, terms, truncs, _ = reference.step(action)
        terminated, truncated = terminated + int(terms[0]), truncated + int(truncs[0] and not terms[0])
    assert terminated > 0 and truncated > 0
    stats = reference.envs[0].obs_rms
    # Elementwise float64 operations in the same order: equal bits by construction, on any CPU.
    assert float(agent.obs_norm.count) == stats.count == 1e-4 + 1 + 400 + terminated + truncated
    np.testing.assert_array_equal(agent.obs_norm.mean.numpy(), stats.mean)
    np.testing.assert_array_equal(agent.obs_norm.var.numpy(), stats.var)


@pytest.mark.parametrize("rows", [1, 7])
def test_observation_statistics_match_gymnasium_bit_for_bit(rows):
    rng = np.random.default_rng(0)
    norm = pgg.RunningObsNorm(3, clip=10.0)
    reference = gym.wrappers.utils.RunningMeanStd(shape=(3,))
    for _ in range(5):
        batch = rng.normal(size=(rows, 3)) * 5 + 2
        norm.update(batch)
        reference.update(batch)
    np.testing.assert_array_equal(norm.mean.numpy(), reference.mean)
    np.testing.assert_array_equal(norm.var.numpy(), reference.var)
    assert float(norm.count) == reference.count
    raw = rng.normal(size=(100, 3)) * 80  # some beyond the clip
    expected = np.clip((raw - reference.mean) / np.sqrt(reference.var + 1e-8), -10, 10).astype(np.float32)
    np.testing.assert_array_equal(norm.normalise(raw), expected)


def test_reward_scaling_matches_gymnasium_bit_for_bit():
    """NormalizeClipReward is gymnasium's NormalizeReward then ClipReward in Python floats: the same
    rewards to the bit, across terminations (which reset the discounted return) and truncations
    (which carry it over)."""

    def env(ours: bool) -> gym.Env:
        base = gym.wrappers.ClipAction(gym.make("Hopper-v4", max_episode_steps=30))
        if ours:
            return pgg.NormalizeClipReward(base, discount=0.99, clip=1.0)
        return gym.wrappers.ClipReward(gym.wrappers.NormalizeReward(base, gamma=0.99), -1.0, 1.0)

    envs = [env(ours=True), env(ours=False)]
    for e in envs:
        e.reset(seed=0)
    ends, rewards = {"terminated": 0, "truncated": 0}, []
    for action in np.random.default_rng(0).uniform(-1, 1, (1000, 3)):
        (_, reward, terminated, truncated, _), (_, expected, *reference_end, _) = (e.step(action) for e in envs)
        assert reward == expected and [terminated, truncated] == reference_end
        rewards.append(reward)
        if terminated or truncated:
            ends["terminated" if terminated else "truncated"] += 1
            for e in envs:
                e.reset()
    assert ends["terminated"] > 3 and ends["truncated"] > 3
    assert max(abs(r) for r in rewards) == 1.0 and min(abs(r) for r in rewards) < 0.5  # clipped and not


@pytest.mark.slow
def test_short_inverted_pendulum_run_learns(tmp_path):
    run_dir = run(
        pgg.Args(env_id="InvertedPendulum-v4", total_timesteps=30_000, guidance=1.1, output_dir=str(tmp_path))
    )
    agent, _ = pgg.load_checkpoint(checkpoints.checkpoint_path(run_dir, 30_000))
    env = gym.make("InvertedPendulum-v4")
    returns = []
    for episode in range(5):
        obs, _ = env.reset(seed=1000 + episode)
        done, total = False, 0.0
        while not done:
            with torch.no_grad():
                action = agent.policy(agent.obs_norm(obs[None]), 1.1).mean[0].numpy()
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done = total + reward, terminated or truncated
        returns.append(total)
    # A random policy balances for about 5 steps.
    assert np.mean(returns) > 150


@pytest.mark.parametrize("env_id", PAPER_TASKS)
def test_paper_task_steps_through_env_factory(env_id):
    if env_id == "Pusher-v4" and checks.argument_error(pgg.Args(env_id=env_id), "continuous") is not None:
        pytest.skip("Pusher-v4 needs mujoco<3, which is not installed")
    envs = training_vector_env(pgg, env_id, 2, seed=0)
    obs, _ = envs.reset(seed=0)
    agent = pgg.Agent(obs.shape[1], envs.single_action_space.shape[0])
    policy = pgg.FastPolicy(agent, 1.1)
    buf = pgg.Rollout.empty(300, 2, obs.shape[1], envs.single_action_space.shape[0])
    _, next_done = pgg.collect_rollout(
        policy, envs, policy.obs_norm.observe(obs), np.zeros(2, np.float32), buf, lambda *_: None, 0
    )
    assert torch.isfinite(buf.obs).all() and buf.rewards.abs().max() <= 10.0
    # First observations, one per step and sub-env, and each episode's last one.
    episode_ends = int(buf.dones[1:].sum() + next_done.sum())
    assert float(agent.obs_norm.count) == pytest.approx(1e-4 + 2 + 600 + episode_ends)


@pytest.mark.parametrize("clip_vloss", [True, False])
@pytest.mark.parametrize("norm_adv", [True, False])
def test_the_ppo_objective_is_cleanrls_with_torch_distributions(clip_vloss, norm_adv):
    """minibatch_loss without guidance is CleanRL's ppo_continuous_action.py loss on a Normal, its
    gradient included, on random data whose ratios and values fall on both sides of the clip range."""
    torch.manual_seed(0)
    agent, rows = pgg.Agent(5, 2), 256
    with torch.no_grad():
        agent.actor_logstd.copy_(torch.tensor([[-0.5, 0.3]]))

    def cleanrl(agent, obs):
        action_mean = agent.actor_mean(obs)
        return Normal(action_mean, torch.exp(agent.actor_logstd.expand_as(action_mean)))

    obs = torch.randn(rows, 5)
    with torch.no_grad():
        actions = cleanrl(agent, obs).sample()
        acted = cleanrl(agent, obs).log_prob(actions).sum(1)
        values = agent.get_value(obs) + 0.3 * torch.randn(rows)
    batch = {"obs": obs, "actions": actions, "logprobs": acted + 0.3 * torch.randn(rows), "values": values,
             "advantages": torch.randn(rows) * 2 + 0.5, "returns": values + torch.randn(rows)}  # fmt: skip
    args = pgg.Args(clip_vloss=clip_vloss, norm_adv=norm_adv, ent_coef=0.01)  # the entropy term too
    assert_minibatch_loss_is_cleanrls(pgg, agent, batch, torch.randperm(rows)[:128], args, cleanrl)
