"""The speed-ups must not change results: each fast path against the reference it replaced."""

import numpy as np
import pytest
import torch
from scipy import stats
from torch.distributions import Categorical, Normal, kl_divergence

import ppo_pgg_continuous as continuous
import ppo_pgg_discrete as discrete


def test_gumbel_max_sampling_matches_categorical_probabilities():
    torch.manual_seed(0)
    logits = torch.tensor([2.0, 0.0, -1.0, 0.5])
    agent = discrete.Agent(4, 4)
    with torch.no_grad():  # an actor whose logits are `logits` whatever the observation
        agent.actor[-1].weight.zero_()
        agent.actor[-1].bias.copy_(logits)
    n = 200_000
    actions, _, _ = discrete.FastPolicy(agent, 1.0).act(np.zeros((n, 4), np.float32), discrete.gumbel_noise(n, 4))
    counts = np.bincount(actions, minlength=4)
    expected = logits.softmax(-1).numpy() * n
    assert stats.chisquare(counts, expected).pvalue > 1e-3
    assert stats.chisquare(counts, np.full(4, n / 4)).pvalue < 1e-10  # the test has power


def test_categorical_log_prob_and_entropy_match_torch_distributions():
    torch.manual_seed(0)
    logits, actions = torch.randn(64, 5), torch.randint(0, 5, (64,))
    ours, reference = discrete.Categorical(logits), Categorical(logits=logits)
    torch.testing.assert_close(ours.log_prob(actions), reference.log_prob(actions))
    torch.testing.assert_close(ours.entropy(), reference.entropy())
    other = torch.randn(64, 5)
    torch.testing.assert_close(
        ours.kl(discrete.Categorical(other)), kl_divergence(reference, Categorical(logits=other))
    )
    numpy_log_prob = discrete.Categorical(logits.numpy()).log_prob(actions.numpy())
    torch.testing.assert_close(torch.from_numpy(numpy_log_prob), reference.log_prob(actions))


def test_gaussian_log_prob_and_entropy_match_torch_distributions():
    torch.manual_seed(0)
    mean, logstd, actions = torch.randn(64, 3), torch.randn(1, 3) * 0.5, torch.randn(64, 3)
    reference, ours = Normal(mean, logstd.exp()), continuous.Gaussian(mean, logstd)
    torch.testing.assert_close(ours.log_prob(actions), reference.log_prob(actions).sum(-1))
    torch.testing.assert_close(ours.entropy().expand(64), reference.entropy().sum(-1))
    other_mean = torch.randn(64, 3)
    same_sigma = continuous.Gaussian(other_mean, logstd)  # one σ: the closed form
    expected = kl_divergence(reference, Normal(other_mean, logstd.exp())).sum(-1)
    torch.testing.assert_close(ours.kl(same_sigma), expected)
    other = continuous.Gaussian(other_mean, torch.randn(1, 3) * 0.5)  # σ per branch: torch.distributions'
    torch.testing.assert_close(ours.kl(other), kl_divergence(reference, Normal(other_mean, other.std)).sum(-1))
    noise = torch.randn(64, 3)
    sample, log_prob = ours.sample_log_prob(noise)
    torch.testing.assert_close(log_prob, reference.log_prob(sample).sum(-1))


@pytest.mark.parametrize("guidance", [1.0, 1.1, 5.0])
def test_rollout_hoisted_null_branch_equals_update_guided_policy(guidance):
    """Rollouts compute pi(.|null) once (a one-row product); updates carry the null row in the batch's
    actor pass. The two agree to float rounding, so the PPO ratio starts at 1 ± 1e-6."""
    torch.manual_seed(0)
    agent, obs = discrete.Agent(4, 2), torch.randn(64, 4)
    cagent, cobs = continuous.Agent(11, 3), torch.randn(64, 11)
    with torch.no_grad():
        agent.null_obs.normal_()
        cagent.null_obs.normal_()
        hoisted = discrete.guide(agent.actor(obs), agent.unconditional_logits(), guidance)
        torch.testing.assert_close(hoisted, agent.policy(obs, guidance).logits, rtol=1e-6, atol=1e-6)
        hoisted = continuous.guide(cagent.actor_mean(cobs), cagent.unconditional_mean(), guidance)
        torch.testing.assert_close(hoisted, cagent.policy(cobs, guidance).mean, rtol=1e-6, atol=1e-6)
    if guidance == 1.0:  # PPO: exactly the same
        assert torch.equal(hoisted, cagent.policy(cobs, guidance).mean)


@pytest.mark.parametrize("guidance", [1.0, 1.1, 5.0])
def test_numpy_rollout_policy_matches_agent(guidance):
    """Rollouts act with a numpy copy of pi_hat and the critic; the update recomputes both in torch.
    They must agree to float rounding, or the first PPO ratio would not start at 1."""
    torch.manual_seed(0)
    agent, obs, gumbel = discrete.Agent(4, 3), torch.randn(64, 4), discrete.gumbel_noise(64, 3)
    with torch.no_grad():
        agent.null_obs.normal_()
        logits = agent.policy(obs, guidance).logits
        actions, logprobs, values = discrete.FastPolicy(agent, guidance).act(obs.numpy(), gumbel)
        assert np.array_equal(actions, (logits + torch.from_numpy(gumbel)).argmax(-1).numpy())
        expected = logits.log_softmax(-1).gather(-1, torch.from_numpy(actions).unsqueeze(-1)).squeeze(-1)
        torch.testing.assert_close(torch.from_numpy(logprobs), expected, rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(torch.from_numpy(values), agent.get_value(obs), rtol=1e-5, atol=1e-6)

    cagent, raw = continuous.Agent(11, 3), np.random.default_rng(0).normal(2.0, 3.0, (64, 11))
    noise = torch.randn(64, 3).numpy()
    with torch.no_grad():
        cagent.null_obs.normal_()
        cagent.actor_logstd.fill_(-1.0)
        policy = continuous.FastPolicy(cagent, guidance)
        obs = policy.obs_norm.observe(raw)
        actions, logprobs, values = policy.act(obs, noise)
        pi = cagent.policy(torch.from_numpy(obs), guidance)
        torch.testing.assert_close(torch.from_numpy(actions), pi.sample(torch.from_numpy(noise)))
        expected = pi.log_prob(torch.from_numpy(actions))
        torch.testing.assert_close(torch.from_numpy(logprobs), expected, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(
            torch.from_numpy(values), cagent.get_value(cagent.obs_norm(raw)), rtol=1e-5, atol=1e-6
        )


def test_numpy_gae_equals_torch_gae_bit_for_bit():
    """GAE runs in numpy; CleanRL's torch loop on the same float32 data gives the same bits."""
    torch.manual_seed(0)
    buf = discrete.Rollout.empty(128, 4, 4)
    buf.rewards.normal_()
    buf.values.normal_()
    buf.dones.bernoulli_(0.05)
    next_value, next_done = torch.randn(4), torch.tensor([0.0, 1.0, 0.0, 1.0])
    advantages, returns = discrete.compute_gae(buf, next_value.numpy(), next_done.numpy(), 0.99, 0.95)
    expected, lastgaelam = torch.zeros_like(buf.rewards), torch.zeros(4)
    for t in reversed(range(128)):
        nextnonterminal = 1.0 - (next_done if t == 127 else buf.dones[t + 1])
        nextvalues = next_value if t == 127 else buf.values[t + 1]
        delta = buf.rewards[t] + 0.99 * nextvalues * nextnonterminal - buf.values[t]
        expected[t] = lastgaelam = delta + 0.99 * 0.95 * nextnonterminal * lastgaelam
    assert torch.equal(advantages, expected) and torch.equal(returns, expected + buf.values)


def test_flat_fused_adam_update_matches_per_tensor_adam():
    """The training scripts' optimizer (fused Adam and clipping on one flat buffer holding every
    parameter) against CleanRL's (per-tensor Adam and clipping): the same update to float rounding."""
    buf = discrete.Rollout.empty(128, 4, 4)
    torch.manual_seed(0)
    buf.obs.normal_()
    buf.actions.random_(0, 2)
    buf.logprobs.fill_(np.log(0.5))
    advantages, returns = torch.randn(128, 4), torch.randn(128, 4)
    args = discrete.Args(guidance=1.1, cond_dropout=0.1)
    results = []
    for flat in (True, False):
        torch.manual_seed(1)
        agent = discrete.Agent(4, 2)
        initial = {key: value.clone() for key, value in agent.state_dict().items()}
        if flat:
            optimizer = torch.optim.Adam(
                [discrete.flatten_parameters(list(agent.parameters()))], lr=args.learning_rate, eps=1e-5, fused=True
            )
        else:
            optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5, foreach=False)
        discrete.ppo_update(agent, optimizer, buf, advantages, returns, args, torch.tensor(args.guidance))
        results.append(agent.state_dict())
    for key in results[0]:
        assert not torch.equal(results[0][key], initial[key]), (
            key
        )  # every parameter, the null embedding included, moved
        torch.testing.assert_close(results[0][key], results[1][key], rtol=1e-5, atol=1e-6)


def rollout_batch(module, num_steps: int, num_envs: int) -> dict[str, torch.Tensor]:
    """A flattened rollout of random data in the layout `ppo_update` hands to `minibatch_loss`."""
    batch_size = num_steps * num_envs
    if module is discrete:
        actions = torch.randint(0, 2, (batch_size,))
    else:
        actions = torch.randn(batch_size, 2)
    return {
        "obs": torch.randn(batch_size, 4),
        "actions": actions,
        "logprobs": torch.randn(batch_size) * 0.1 - 1.0,
        "advantages": torch.randn(batch_size),
        "returns": torch.randn(batch_size),
        "values": torch.randn(batch_size),
    }


@pytest.mark.slow
@pytest.mark.parametrize("module", [discrete, continuous], ids=["discrete", "continuous"])
def test_compiled_minibatch_loss_matches_eager(module):
    """--compile: the compiled loss, its statistics and its gradient agree with the eager ones to
    float rounding; inductor fuses the ops and may sum in another order, so not bit for bit."""
    torch.manual_seed(0)
    agent = module.Agent(4, 2)
    with torch.no_grad():
        agent.null_obs.normal_()
    batch = rollout_batch(module, 64, 4)  # the shapes of tests/test_discrete.py's small runs
    mb_inds, drop_mask = torch.randperm(256)[:64], torch.rand(64) < 0.25
    args = module.Args(guidance=1.1, cond_dropout=0.25)
    results = []
    for loss_fn in (module.minibatch_loss, torch.compile(module.minibatch_loss)):
        agent.zero_grad()
        loss, stats = loss_fn(agent, batch, mb_inds, drop_mask, torch.tensor(args.guidance), args)
        loss.backward()
        results.append((loss.detach(), stats, {name: p.grad.clone() for name, p in agent.named_parameters()}))
    (eager_loss, eager_stats, eager_grads), (compiled_loss, compiled_stats, compiled_grads) = results
    torch.testing.assert_close(compiled_loss, eager_loss, rtol=1e-5, atol=1e-6)
    for key in eager_stats:
        torch.testing.assert_close(compiled_stats[key], eager_stats[key], rtol=1e-5, atol=1e-6)
    for name, grad in eager_grads.items():
        assert grad.abs().max() > 0, name  # every parameter, the null embedding included, gets gradient
        torch.testing.assert_close(compiled_grads[name], grad, rtol=1e-4, atol=1e-6)
