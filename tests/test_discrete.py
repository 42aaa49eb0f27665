from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import assert_minibatch_loss_is_cleanrls, small_args, train, training_vector_env
from torch import nn
from torch.distributions import Categorical

import ppo_pgg_discrete as pgg
from pgg_utils import checkpoints
from pgg_utils.guidance import uses_null_branch
from pgg_utils.tasks import TASK_EPISODE


def tiny_args(tmp_path, **overrides) -> pgg.Args:
    """Two checkpoints of PPO on CartPole, 8 iterations of 256 steps."""
    return small_args("discrete", tmp_path, **{"total_timesteps": 2048, "checkpoint_interval": 1024, "guidance": 1.0,
                                               "cond_dropout": 0.0, **overrides})  # fmt: skip


def run(args: pgg.Args):
    return train(pgg, args)


# --- the guided distribution ------------------------------------------------------------------


class FixedLogits(nn.Module):
    """An actor that returns given null logits for the null embedding and given conditional logits
    for the batch rows: guidance arithmetic on arbitrary logits."""

    def __init__(self, logits_cond, logits_null):
        super().__init__()
        self.register_buffer("cond", logits_cond)
        self.register_buffer("null", logits_null.unsqueeze(0))

    def forward(self, x):
        if len(x) == 1:  # unconditional_logits()
            return self.null
        if len(x) == len(self.cond):  # policy at γ=1: the batch alone
            return self.cond
        return torch.cat([self.cond, self.null])  # policy: the batch plus the null row


def FixedLogitsAgent(logits_cond, logits_null):
    agent = pgg.Agent(obs_dim=1, n_actions=logits_cond.shape[-1])
    agent.actor = FixedLogits(logits_cond, logits_null)
    return agent


@pytest.mark.parametrize("guidance", [0.0, 0.5, 1.0, 1.1, 2.0, 5.0])
def test_guided_policy_is_normalised_product(guidance):
    torch.manual_seed(0)
    logits_cond, logits_null = torch.randn(16, 5, dtype=torch.float64), torch.randn(5, dtype=torch.float64)
    agent = FixedLogitsAgent(logits_cond, logits_null).double()
    guided = agent.policy(torch.zeros(16, 1, dtype=torch.float64), guidance).logits.softmax(-1)
    unnormalised = logits_null.softmax(-1) ** (1 - guidance) * logits_cond.softmax(-1) ** guidance
    expected = unnormalised / unnormalised.sum(-1, keepdim=True)
    torch.testing.assert_close(guided, expected, rtol=1e-10, atol=1e-12)
    if guidance == 1.0:
        torch.testing.assert_close(guided, logits_cond.softmax(-1), rtol=0, atol=0)
    if guidance == 0.0:
        torch.testing.assert_close(guided, logits_null.softmax(-1).expand(16, 5), rtol=1e-12, atol=0)


@pytest.mark.parametrize("guidance", [20.0, 100.0])
def test_large_guidance_stays_finite(guidance):
    torch.manual_seed(0)
    agent = FixedLogitsAgent(10 * torch.randn(64, 3), 10 * torch.randn(3))
    logp = agent.policy(torch.zeros(64, 1), guidance).logits.log_softmax(-1)
    assert torch.isfinite(logp.exp()).all() and torch.allclose(logp.exp().sum(-1), torch.ones(64))
    assert torch.isfinite(-(logp.exp() * logp.clamp_min(-1e30)).sum(-1)).all()


def test_policy_gradient_identity_normaliser_vanishes():
    """E_{a~pi_hat}[A ∇log pi_hat] = E_{a~pi_hat}[A (γ∇log pi_s + (1-γ)∇log pi_null)] when E[A]=0,
    with exact expectations over the actions; and not without centring (the Z(s) term is real)."""
    torch.manual_seed(0)
    guidance = 1.7
    agent = pgg.Agent(obs_dim=3, n_actions=4).double()
    with torch.no_grad():
        agent.null_obs.normal_()
        agent.actor[-1].weight.mul_(100)  # leave the near-uniform initial regime
    obs = torch.randn(1, 3, dtype=torch.float64)
    params = list(agent.actor.parameters()) + [agent.null_obs]

    def grads(advantage_fn):
        logp_hat = agent.policy(obs, guidance).logits.log_softmax(-1)[0]
        pi_hat = logp_hat.exp().detach()
        advantages = advantage_fn(pi_hat)
        lhs = torch.autograd.grad((pi_hat * advantages * logp_hat).sum(), params)
        logp_cond = agent.actor(obs)[0].log_softmax(-1)
        logp_null = agent.unconditional_logits().log_softmax(-1)
        mixed = guidance * logp_cond + (1 - guidance) * logp_null
        rhs = torch.autograd.grad((pi_hat * advantages * mixed).sum(), params)
        return torch.cat([g.flatten() for g in lhs]), torch.cat([g.flatten() for g in rhs])

    raw = torch.tensor([1.0, -2.0, 0.5, 3.0], dtype=torch.float64)
    lhs, rhs = grads(lambda pi: raw - (pi * raw).sum())
    torch.testing.assert_close(lhs, rhs, rtol=1e-9, atol=1e-12)
    assert lhs.abs().max() > 1e-3
    lhs, rhs = grads(lambda pi: raw)
    assert (lhs - rhs).abs().max() > 1e-3


# --- gradient into the null embedding -----------------------------------------------------------


def null_grad_after_update(guidance, cond_dropout):
    torch.manual_seed(0)
    agent = pgg.Agent(obs_dim=4, n_actions=2)
    optimizer = torch.optim.Adam(agent.parameters(), lr=1e-3)
    buf = pgg.Rollout.empty(32, 2, 4)
    buf.obs.normal_()
    buf.actions.random_(0, 2)
    buf.logprobs.fill_(np.log(0.5))
    args = pgg.Args(guidance=guidance, cond_dropout=cond_dropout, update_epochs=1, num_minibatches=1)
    guidance = torch.tensor(args.guidance) if uses_null_branch(args) else None  # as train() decides
    pgg.ppo_update(agent, optimizer, buf, torch.randn(32, 2), torch.randn(32, 2), args, guidance)
    grad = agent.null_obs.grad
    return (None if grad is None else grad.clone()), agent.null_obs.detach().clone()


def test_null_embedding_gets_no_gradient_at_guidance_one():
    grad, value = null_grad_after_update(1.0, 0.0)
    assert grad is None and torch.equal(value, torch.zeros(4))


@pytest.mark.parametrize("guidance,cond_dropout", [(1.1, 0.0), (1.0, 0.3), (0.5, 0.0)])
def test_null_embedding_learns_otherwise(guidance, cond_dropout):
    grad, value = null_grad_after_update(guidance, cond_dropout)
    assert grad.abs().sum() > 0 and value.abs().sum() > 0


class VanillaAgent(pgg.Agent):
    """CleanRL's agent: the same networks and initialisation, no null embedding, no guidance."""

    def __init__(self, obs_dim, n_actions):
        super().__init__(obs_dim, n_actions)
        del self.null_obs

    def unconditional_logits(self):
        return torch.zeros(self.actor[-1].out_features)  # `guide` is patched to return the conditional branch

    def branches(self, obs, drop_mask=None):
        cond = pgg.Categorical(self.actor(obs))
        return cond, cond  # `guide` is patched to return the conditional branch


def test_guidance_one_is_exactly_vanilla_ppo(tmp_path, monkeypatch):
    args = tiny_args(tmp_path, total_timesteps=4096, guidance=1.0, cond_dropout=0.0)
    pgg_ckpt = torch.load(checkpoints.checkpoint_path(run(args), 4096), weights_only=True)
    monkeypatch.setattr(pgg, "Agent", VanillaAgent)
    monkeypatch.setattr(pgg, "guide", lambda cond, null, guidance: cond)
    monkeypatch.setattr(pgg, "guidance_diagnostics", lambda *a: {})
    vanilla_ckpt = torch.load(
        checkpoints.checkpoint_path(run(replace(args, run_name="vanilla")), 4096), weights_only=True
    )
    assert set(pgg_ckpt["model"]) - set(vanilla_ckpt["model"]) == {"null_obs"}
    for key, value in vanilla_ckpt["model"].items():
        assert torch.equal(pgg_ckpt["model"][key], value), key
    assert torch.equal(pgg_ckpt["model"]["null_obs"], torch.zeros(4))


# --- Gymnasium 1.x autoreset --------------------------------------------------------------------


class CountdownEnv(gym.Env):
    """Episodes of a fixed length; the observation is (episode index, step in episode)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, length):
        self.length, self.episode, self.t = length, -1, 0

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.episode, self.t = self.episode + 1, 0
        return np.array([self.episode, 0], np.float32), {}

    def step(self, action):
        self.t += 1
        obs = np.array([self.episode, self.t], np.float32)
        return obs, float(self.t), self.t == self.length, False, {}


def test_rollout_buffer_at_episode_boundaries(monkeypatch):
    lengths = [3, 5]
    countdown = lambda: gym.wrappers.RecordEpisodeStatistics(CountdownEnv(lengths.pop(0)), stats_key=TASK_EPISODE)
    monkeypatch.setattr(pgg, "make_env", lambda env_id, video_dir=None: countdown)
    envs = training_vector_env(pgg, "unused", 2, seed=0)
    obs, _ = envs.reset(seed=0)
    buf = pgg.Rollout.empty(7, 2, 2)
    episodes = []
    next_obs, next_done = pgg.collect_rollout(
        pgg.FastPolicy(pgg.Agent(2, 2), 1.0), envs, obs, np.zeros(2, np.float32), buf,
        lambda r, l, step: episodes.append((r, l, step)), global_step=100,
    )  # fmt: skip
    # env 0: episodes of 3 steps. Every stored obs is a pre-action state; a terminal obs never is.
    assert buf.obs[:, 0].tolist() == [[0, 0], [0, 1], [0, 2], [1, 0], [1, 1], [1, 2], [2, 0]]
    assert buf.dones[:, 0].tolist() == [0, 0, 0, 1, 0, 0, 1]
    assert buf.rewards[:, 0].tolist() == [1, 2, 3, 1, 2, 3, 1]
    assert buf.obs[:, 1].tolist() == [[0, 0], [0, 1], [0, 2], [0, 3], [0, 4], [1, 0], [1, 1]]
    assert buf.dones[:, 1].tolist() == [0, 0, 0, 0, 0, 1, 0]
    assert next_obs.tolist() == [[2, 1], [1, 2]] and next_done.tolist() == [0, 0]
    # Each episode is logged at the global step it ended at (CleanRL's), 2 env steps per vector step:
    # env 0's end after vector steps 3 and 6, env 1's after step 5.
    assert sorted(episodes) == [(6.0, 3, 106), (6.0, 3, 112), (15.0, 5, 110)]
    # GAE must not bootstrap across a boundary: with zero values the advantage is the in-episode return.
    buf.values.zero_()
    advantages, _ = pgg.compute_gae(buf, np.zeros(2, np.float32), next_done, discount=1.0, gae_lambda=1.0)
    assert advantages[:, 0].tolist()[:3] == [6, 5, 3] and advantages[:, 1].tolist()[:5] == [15, 14, 12, 9, 5]


# --- checkpoints, determinism, learning ---------------------------------------------------------


def test_checkpoints_round_trip_under_weights_only(tmp_path):
    run_dir = run(tiny_args(tmp_path, guidance=1.1, total_timesteps=2500))
    files = sorted(p.name for p in (run_dir / "checkpoints").iterdir())
    assert files == ["step_000001024.pt", "step_000002048.pt", "step_000002500.pt"]
    assert (run_dir / "args.json").exists() and list(run_dir.glob("events.out.tfevents.*"))
    agent, ckpt = pgg.load_checkpoint(run_dir / "checkpoints" / "step_000002500.pt")
    assert ckpt["global_step"] == 2560 and ckpt["step_mark"] == 2500 and ckpt["env_id"] == "CartPole-v1"
    assert ckpt["args"]["guidance"] == 1.1 and ckpt["action_space"] == "discrete"
    first, _ = pgg.load_checkpoint(run_dir / "checkpoints" / "step_000001024.pt")
    assert not torch.equal(first.null_obs, agent.null_obs)
    assert not list(run_dir.rglob("*.tmp"))


@pytest.mark.slow
def test_same_seed_same_result(tmp_path):
    args = tiny_args(tmp_path, cond_dropout=0.1, guidance=1.1)
    a = torch.load(checkpoints.checkpoint_path(run(args), 2048), weights_only=True)["model"]
    b = torch.load(checkpoints.checkpoint_path(run(replace(args, run_name="again")), 2048), weights_only=True)["model"]
    c = torch.load(checkpoints.checkpoint_path(run(replace(args, run_name="other", seed=2)), 2048), weights_only=True)[
        "model"
    ]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def evaluate(agent, guidance, episodes=10, seed=1000):
    env = gym.make("CartPole-v1")
    policy, rng = pgg.FastPolicy(agent, guidance), np.random.default_rng(seed)
    returns = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        done, total = False, 0.0
        while not done:
            actions, _, _ = policy.act(obs[None], rng.gumbel(size=(1, 2)))
            obs, reward, terminated, truncated, _ = env.step(int(actions[0]))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


@pytest.mark.slow
def test_short_cartpole_run_learns(tmp_path):
    run_dir = run(pgg.Args(total_timesteps=50_000, guidance=1.1, output_dir=str(tmp_path)))
    agent, _ = pgg.load_checkpoint(checkpoints.checkpoint_path(run_dir, 50_000))
    # A random policy scores about 22. A broken GAE or autoreset stays far below this.
    assert evaluate(agent, 1.1) > 150


@pytest.mark.parametrize("clip_vloss", [True, False])
@pytest.mark.parametrize("norm_adv", [True, False])
def test_the_ppo_objective_is_cleanrls_with_torch_distributions(clip_vloss, norm_adv):
    """minibatch_loss without guidance is CleanRL's ppo.py loss on a Categorical, its gradient included,
    on random data whose ratios and values fall on both sides of the clip range."""
    torch.manual_seed(0)
    agent, rows = pgg.Agent(4, 3), 256
    obs, actions = torch.randn(rows, 4), torch.randint(0, 3, (rows,))
    with torch.no_grad():
        acted = Categorical(logits=agent.actor(obs)).log_prob(actions)
        values = agent.get_value(obs) + 0.3 * torch.randn(rows)
    batch = {"obs": obs, "actions": actions, "logprobs": acted + 0.3 * torch.randn(rows), "values": values,
             "advantages": torch.randn(rows) * 2 + 0.5, "returns": values + torch.randn(rows)}  # fmt: skip
    args = pgg.Args(clip_vloss=clip_vloss, norm_adv=norm_adv)
    cleanrl = lambda agent, obs: Categorical(logits=agent.actor(obs))
    assert_minibatch_loss_is_cleanrls(pgg, agent, batch, torch.randperm(rows)[:128], args, cleanrl)
