"""The guided policy is defined once in each training script (`guided_policy`): a fork edits that one place and
every path follows (the loss, the rollouts' numpy copy, `act`); a fork that edits one path alone stops before
training in one line. Also what acting and training refuse, and what a checkpoint records of its task."""

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT, SCRIPTS, one_line_error, small_args, train
from torch import nn

import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import checkpoints, evaluation, policy, runs, scripts

# --- a fork that mixes σ per branch: the one place ---------------------------------------------------

# The fork's edits: a σ of its own for pi(.|null), and guided_policy mixing the Gaussians' natural parameters
# (precision (1-γ)/σ_null² + γ/σ_s², and precision·mean likewise), written once with operations numpy has (the
# rollouts then derive their numpy copy from it) and once with torch's alone (the rollouts fall back to torch).
SIGMA_PARAMETER = (
    "        self.actor_logstd = nn.Parameter(torch.zeros(1, action_dim))\n",
    (
        "        self.actor_logstd = nn.Parameter(torch.zeros(1, action_dim))\n"
        "        self.own_null_logstd = nn.Parameter(torch.zeros(1, action_dim))\n"
    ),
)
SIGMA_OF_NULL = ("        return self.actor_logstd  # PGG\n", "        return self.own_null_logstd\n")
MIX = "    return Gaussian(guide(cond.mean, null.mean, guidance), cond.logstd, cond.std)  # PGG\n"
NATURAL_MIX = {
    "numpy": "    precision_cond, precision_null = cond.std**-2, null.std**-2\n"
    "    precision = guide(precision_cond, precision_null, guidance)\n"
    "    mean = guide(cond.mean * precision_cond, null.mean * precision_null, guidance) / precision\n"
    "    return Gaussian(mean, std=precision**-0.5)\n",
    "torch": "    precision_cond, precision_null = torch.exp(-2 * cond.logstd), torch.exp(-2 * null.logstd)\n"
    "    precision = torch.lerp(precision_null, precision_cond, guidance)\n"
    "    mean = torch.lerp(null.mean * precision_null, cond.mean * precision_cond, guidance) / precision\n"
    "    return Gaussian(mean, logstd=-0.5 * torch.log(precision))\n",
}


def write_fork(folder: Path, original: str, *edits: tuple[str, str], name: str = "ppo_pgg_fork.py") -> Path:
    """A copy of a training script with each (old, new) edit applied; every `old` must be in it once."""
    source = (ROOT / original).read_text()
    for old, new in edits:
        assert source.count(old) == 1, old
        source = source.replace(old, new)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text(source)
    return folder / name


def replayed_actions(agent, raw: np.ndarray, guidance: float, noise: np.ndarray) -> np.ndarray:
    """The σ fork's policy, replayed apart from its code: the product N(μ_null, σ_null)^(1-γ)·N(μ_s, σ_s)^γ in
    float64, sampled with `noise` and clipped to the task's bounds."""
    with torch.no_grad():
        obs = torch.from_numpy(agent.obs_norm.normalise(raw)).double()
        actor = {name: p.double() for name, p in agent.actor_mean.named_parameters()}
        forward = lambda x: torch.func.functional_call(agent.actor_mean, actor, (x,))
        mean_cond, mean_null = forward(obs), forward(agent.null_obs.double()[None])
        precision_cond = torch.exp(-2 * agent.actor_logstd.double())
        precision_null = torch.exp(-2 * agent.own_null_logstd.double())
        precision = (1 - guidance) * precision_null + guidance * precision_cond
        mean = ((1 - guidance) * precision_null * mean_null + guidance * precision_cond * mean_cond) / precision
        actions = (mean + precision**-0.5 * torch.from_numpy(noise).double()).numpy()
    return np.clip(actions, *agent.action_bounds)


@pytest.mark.slow
@pytest.mark.parametrize("written_for", ["numpy", "torch"])
def test_a_fork_that_mixes_sigma_per_branch_in_the_one_place_trains_and_acts_as_its_policy(tmp_path, written_for):
    fork = write_fork(tmp_path / "fork", "ppo_pgg_continuous.py", SIGMA_PARAMETER, SIGMA_OF_NULL,
                      (MIX, NATURAL_MIX[written_for]))  # fmt: skip
    module = scripts.load_module(fork)
    run_dir = train(module, small_args("continuous", tmp_path / "runs", guidance=1.3, cond_dropout=0.0))
    agent, ckpt = module.load_checkpoint(checkpoints.checkpoints_of(run_dir)[-1])
    # guidance trained the null branch's own σ; set it well apart from the policy's so the replay has power
    assert not torch.equal(agent.own_null_logstd, torch.zeros_like(agent.own_null_logstd))
    with torch.no_grad():
        agent.own_null_logstd.copy_(agent.actor_logstd + 0.7)
    rng = np.random.default_rng(0)
    raw, noise = rng.normal(size=(6, ckpt["obs_dim"])), rng.standard_normal((6, ckpt["action_dim"])).astype(np.float32)
    for guidance in (0.5, 1.0, 2.0):
        expected = replayed_actions(agent, raw, guidance, noise)
        np.testing.assert_allclose(agent.act(raw, guidance, noise=noise), expected, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(agent.act(raw, np.full(6, guidance), noise=noise), expected, rtol=1e-4, atol=1e-5)
        for row in range(2):  # one observation at a time, as the sweep's sequential path acts
            single = agent.act(raw[row], np.array([guidance]), noise=noise[row : row + 1])
            np.testing.assert_allclose(single, expected[row], rtol=1e-4, atol=1e-5)
    # with the original's shared-σ mean mix the same weights act otherwise
    shared = ppo_pgg_continuous.Gaussian(agent.policy(agent.obs_norm(raw), 2.0).mean)
    assert not np.allclose(replayed_actions(agent, raw, 2.0, noise), np.clip(shared.mean.detach().numpy(), -0.4, 0.4))
    # the sweep's episodes are the replayed policy's: the same task steps, actions and noise, apart from its code
    guided = evaluation.GuidedPolicy(agent, ckpt, module=module)
    swept = evaluation.evaluate_cell(guided, ckpt, 2.0, 2, 10_000, False)["return"]
    for episode, swept_return in enumerate(swept):
        env = module.make_env(ckpt["env_id"])()
        horizon, size = evaluation.horizon_and_action_size(env, ckpt)
        episode_noise = evaluation.episode_noise("continuous", 10_000, episode, horizon, size)
        obs, _ = env.reset(seed=10_000 + episode)
        total, done, t = 0.0, False, 0
        while not done:
            action = replayed_actions(agent, obs[None], 2.0, episode_noise[t : t + 1])[0]
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done, t = total + float(reward), terminated or truncated, t + 1
        assert swept_return == pytest.approx(total, rel=1e-4), episode


# --- a fork that edits one path alone stops before training -------------------------------------------

ONE_PATH = {
    "rollout": (
        "ppo_pgg_continuous.py",
        ("        return actions, log_probs, self.value(obs)\n",
         "        return np.tanh(actions), log_probs, self.value(obs)  # squashed here only\n"),
        "the rollouts' actions (FastPolicy.act) differ from guided_policy's samples at guidance 1.3",
    ),
    "loss": (
        "ppo_pgg_continuous.py",
        ("    newlogprob = pi.log_prob(batch[\"actions\"][mb_inds])\n",
         ("    newlogprob = pi.log_prob(batch[\"actions\"][mb_inds]) - torch.log(1 - torch.tanh(batch[\"actions\"][mb_inds])"
         " ** 2 + 1e-6).sum(-1)\n")),
        "minibatch_loss's log-probabilities of the rollouts' actions differ from the rollouts' own at guidance 1.3",
    ),
    "act": (
        "ppo_pgg_discrete.py",
        ("        return guided_actions(self, obs, guidance, deterministic, noise, logits_null, draw, seed)  # PGG\n",
         ("        actions = guided_actions(self, obs, guidance, deterministic, noise, logits_null, draw, seed)\n"
          "        return self.acting_policy(obs, np.asarray(guidance)).logits.argmin(-1) if deterministic else actions\n")),
        "Agent.act's deterministic actions differ from guided_policy's mode at guidance 1.3",
    ),
}  # fmt: skip


@pytest.mark.parametrize("path", ONE_PATH)
def test_a_fork_that_edits_one_path_alone_stops_before_training_in_one_line(tmp_path, capsys, path):
    original, edit, message = ONE_PATH[path]
    module = scripts.load_module(write_fork(tmp_path / "fork", original, edit))
    kind = "discrete" if "discrete" in original else "continuous"
    args = small_args(kind, tmp_path / "runs", run_name="one_path")
    with pytest.raises(SystemExit) as stopped:
        train(module, args)
    err = capsys.readouterr().err.strip().splitlines()
    assert stopped.value.code == 2 and len(err) == 1 and err[0].startswith(f"error: {message} on a probe batch")
    assert not list((tmp_path / "runs" / "one_path").glob(runs.EVENTS_GLOB))  # nothing written to start again over


@pytest.mark.slow
def test_a_fork_that_edits_one_path_alone_exits_2_in_one_line_as_a_command(tmp_path):
    original, edit, message = ONE_PATH["rollout"]
    fork = write_fork(tmp_path / "fork", original, edit)
    proc = subprocess.run(
        [sys.executable, str(fork), "--env-id", "Hopper-v4", "--output-dir", str(tmp_path / "runs")],
        capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )  # fmt: skip
    assert one_line_error(proc).startswith(f"error: {message} on a probe batch")


def test_an_agent_without_a_method_the_project_calls_is_named_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.delattr(ppo_pgg_discrete.Agent, "unconditional_logits")
    with pytest.raises(SystemExit) as stopped:
        train(ppo_pgg_discrete, small_args("discrete", tmp_path))
    assert stopped.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: Agent has no method unconditional_logits, which the sweep calls (see the Agent's docstring)"
    ]


# --- BatchNorm and Dropout in the actor -------------------------------------------------------------------


def with_batch_norm(agent, network: str):
    """The researcher's edit: BatchNorm1d after each hidden Linear of the actor."""
    layers = []
    for layer in getattr(agent, network):
        layers.append(layer)
        if isinstance(layer, nn.Linear) and layer is not getattr(agent, network)[-1]:
            layers.append(nn.BatchNorm1d(layer.out_features))
    setattr(agent, network, nn.Sequential(*layers))
    return agent


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("guidance", [1.0, 1.1])
def test_an_actor_with_batch_norm_trains_with_and_without_guidance(kind, guidance, tmp_path, monkeypatch):
    module = SCRIPTS[kind]
    network = "actor" if kind == "discrete" else "actor_mean"
    real_agent = module.Agent
    monkeypatch.setattr(module, "Agent", lambda *a, **k: with_batch_norm(real_agent(*a, **k), network))
    run_dir = train(module, small_args(kind, tmp_path, guidance=guidance, cond_dropout=0.0))
    agent, ckpt = module.load_checkpoint(checkpoints.checkpoints_of(run_dir)[-1])
    norm = getattr(agent, network)[1]
    assert isinstance(norm, nn.BatchNorm1d) and norm.num_batches_tracked > 0  # the updates trained it
    raw = np.random.default_rng(0).normal(size=(1, ckpt["obs_dim"]))
    assert np.isfinite(np.asarray(agent.act(raw, 1.5), dtype=np.float64)).all()  # one row acts
    swept = evaluation.evaluate_cell(evaluation.GuidedPolicy(agent, ckpt, module=module), ckpt, 1.5, 2, 10_000, False)
    assert np.isfinite(swept["return"]).all() and (swept["length"] > 0).all()  # the sweep's batched episodes
    running = norm.running_mean.clone()
    evaluation.evaluate_cell(evaluation.GuidedPolicy(agent, ckpt, module=module), ckpt, 1.5, 1, 10_000, False)
    assert torch.equal(norm.running_mean, running)  # evaluation moves no statistics


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_the_null_branch_moves_no_batch_norm_statistics(kind):
    module = SCRIPTS[kind]
    network = "actor" if kind == "discrete" else "actor_mean"
    torch.manual_seed(0)
    agent = with_batch_norm(module.Agent(4, 3), network)  # in training mode
    norm = getattr(agent, network)[1]
    before = {name: value.clone() for name, value in norm.state_dict().items()}
    obs = torch.randn(16, 4)
    with torch.no_grad():  # the rollouts and the diagnostics move nothing
        module.FastPolicy(agent, 1.5).act(obs.numpy(), np.zeros((16, 3), np.float32))
        policy.guidance_diagnostics(module, agent, obs, 1.5)
    assert all(torch.equal(value, norm.state_dict()[name]) for name, value in before.items())
    getattr(agent, network)(obs)  # PPO's update: the batch alone moves the statistics
    batch_alone = norm.running_mean.clone()
    norm.load_state_dict(before)
    agent.policy(obs, 1.5)  # PGG's: the null row is no part of the batch
    assert torch.equal(norm.running_mean, batch_alone) and not torch.equal(batch_alone, before["running_mean"])


# --- what acting and training refuse --------------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_names_both_shapes_of_an_observation_of_another_shape(kind):
    agent = SCRIPTS[kind].Agent(4, 3)
    for obs, shape in ((np.zeros(5), "(5,)"), (np.float64(0.0), "()"), (np.zeros((4, 1)), "(4, 1)"),
                       (np.zeros((2, 2, 4)), "(2, 2, 4)")):  # fmt: skip
        with pytest.raises(ValueError) as refused:
            agent.act(obs, 1.0)
        assert (
            str(refused.value) == f"the observation has shape {shape}; the agent takes (4,), or a batch of them (n, 4)"
        )
    with pytest.raises(ValueError, match=r"^guidance must be a number in \[0, 1000\], got None$"):
        agent.act(np.zeros(4), None)


class ShiftedActions(gym.Wrapper):
    """CartPole with its actions numbered from -1: Discrete(2, start=-1)."""

    def __init__(self):
        super().__init__(gym.make("CartPole-v1", max_episode_steps=50))
        self.action_space = gym.spaces.Discrete(2, start=-1)

    def step(self, action):
        assert action in self.action_space, action
        return self.env.step(int(action) + 1)


class MatrixActions(gym.Wrapper):
    """Pendulum with a (2, 2) action matrix whose first entry is the torque."""

    def __init__(self):
        super().__init__(gym.make("Pendulum-v1", max_episode_steps=50))
        self.action_space = gym.spaces.Box(-2.0, 2.0, (2, 2), np.float32)

    def step(self, action):
        return self.env.step(np.asarray(action).reshape(2, 2)[:1, 0])


@pytest.mark.parametrize(
    "kind,entry_point,message",
    [("discrete", ShiftedActions, ("ShiftedActions-v0's actions start at -1; this script acts with 0..n-1: shift them "
      "in make_env (gymnasium.wrappers.TransformAction) or start the space at 0")),
     ("continuous", MatrixActions, ("MatrixActions-v0's actions have shape (2, 2); this script acts with a vector (a "
      "1-D Box): reshape them in make_env"))],
)  # fmt: skip
def test_an_action_space_the_agent_cannot_act_in_is_refused_before_training(
    kind, entry_point, message, tmp_path, capsys
):
    env_id = f"{entry_point.__name__}-v0"
    gym.register(env_id, entry_point=entry_point)
    try:
        args = replace(small_args(kind, tmp_path), env_id=env_id)
        with pytest.raises(SystemExit) as stopped:
            train(SCRIPTS[kind], args)
    finally:
        gym.registry.pop(env_id)
    assert stopped.value.code == 2 and capsys.readouterr().err.strip().splitlines() == [f"error: {message}"]


# --- the checkpoint's contract, and returns that are the task's own ----------------------------------


def events(run_dir, tag: str) -> list[float]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    accumulator.Reload()
    return [event.value for event in accumulator.Scalars(tag)]


def test_a_reward_scale_in_make_env_leaves_the_logged_returns_raw_and_the_checkpoint_records_the_spaces(tmp_path):
    scaled = ("        return env\n",
              "        return gym.wrappers.TransformReward(env, lambda reward: 0.1 * reward)\n")  # fmt: skip
    module = scripts.load_module(write_fork(tmp_path / "fork", "ppo_pgg_discrete.py", scaled))
    env = module.make_env("CartPole-v1")()
    env.reset(seed=0)
    assert env.step(0)[1] == pytest.approx(0.1)  # the learner sees the scale
    run_dir = train(module, small_args("discrete", tmp_path / "runs"))
    returns, lengths = events(run_dir, "charts/episodic_return"), events(run_dir, "charts/episodic_length")
    assert len(returns) > 10 and returns == lengths  # CartPole pays 1 a step: the task's own return
    ckpt = torch.load(checkpoints.checkpoints_of(run_dir)[-1], weights_only=True)
    assert ckpt["task_spaces"] == {"observation": {"shape": [4]}, "action": {"type": "Discrete", "n": 2, "start": 0}}


def test_a_continuous_checkpoint_records_the_spaces_the_agent_saw_and_the_tasks_bounds(tmp_path):
    ckpt = torch.load(checkpoints.checkpoints_of(train(ppo_pgg_continuous, small_args("continuous", tmp_path)))[-1],
                      weights_only=True)  # fmt: skip
    action = ckpt["task_spaces"]["action"]
    assert ckpt["task_spaces"]["observation"] == {"shape": [376]}
    assert action["type"] == "Box" and action["shape"] == [17]
    assert action["low"] == pytest.approx([-0.4] * 17) and action["high"] == pytest.approx([0.4] * 17)


def test_the_start_up_check_draws_nothing_and_moves_nothing(tmp_path):
    """The probe runs between seeding and the first rollout: torch's RNG, the observation statistics and the
    weights are as they were (so the paper's runs keep their bits: benchmarks/compare_revisions.py)."""
    agent = ppo_pgg_continuous.Agent(11, 3)
    args = ppo_pgg_continuous.Args(guidance=1.1)
    state = {name: value.clone() for name, value in agent.state_dict().items()}
    torch.manual_seed(5)
    rng = torch.get_rng_state()
    raw = policy.probe_observations(gym.spaces.Box(-np.inf, np.inf, (11,)))
    noise = np.random.default_rng(1).standard_normal((len(raw), 3)).astype(np.float32)
    assert policy.path_error(ppo_pgg_continuous, agent, args, raw, agent.obs_norm.normalise, noise) is None
    assert torch.equal(torch.get_rng_state(), rng) and agent.training
    assert all(torch.equal(value, agent.state_dict()[name]) for name, value in state.items())


class CountingActor(ppo_pgg_discrete.Agent):
    """An actor with a hidden state: the steps since its reset, which it acts on."""

    def __init__(self):
        super().__init__(4, 2)
        self.steps, self.first_steps = 0, []

    def reset(self):
        self.steps = 0

    def act(self, obs, guidance=1.0, deterministic=False, noise=None, logits_null=None):
        self.steps += 1
        if self.steps == 1 or not self.first_steps:
            self.first_steps.append(self.steps)
        return np.full(len(obs), int(self.steps % 7 < 3))


def test_every_sweep_episode_starts_the_actor_from_a_fresh_state():
    agent = CountingActor()
    ckpt = {"action_space": "discrete", "env_id": "CartPole-v1", "n_actions": 2}
    guided = evaluation.GuidedPolicy(agent, ckpt, module=ppo_pgg_discrete)
    lengths = [evaluation.evaluate_cell(guided, ckpt, 1.0, 1, 10_000 + k, True)["length"][0] for k in range(3)]
    evaluation.evaluate_cell(guided, ckpt, 1.0, 2, 10_000, True)
    assert min(lengths) > 1 and agent.first_steps == [1, 1, 1, 1]  # three cells of one episode, then a cell of two


def test_a_definition_written_for_torch_alone_acts_through_torch(monkeypatch):
    """guided_policy with torch functions only: the numpy paths (rollouts, act, bc_null) compute it on tensors."""
    module = ppo_pgg_discrete
    torch.manual_seed(0)
    agent, obs = module.Agent(4, 3), np.random.default_rng(0).normal(size=(5, 4)).astype(np.float32)
    with torch.no_grad():
        agent.null_obs.normal_()
    expected = agent.act(obs, 1.7, deterministic=True)
    monkeypatch.setattr(module, "guided_policy", lambda c, n, g: module.Categorical(torch.lerp(n.logits, c.logits, g)))
    pi = agent.acting_policy(obs, 1.7)
    assert isinstance(pi, policy.TorchDefined) and isinstance(pi.logits, np.ndarray)
    np.testing.assert_array_equal(agent.act(obs, np.full(5, 1.7), deterministic=True), expected)
    assert agent.act(obs, 1.7).shape == (5,)  # its own noise, shaped by the logits
    actions, log_probs, _ = module.FastPolicy(agent, 1.7).act(obs, module.gumbel_noise(5, 3))
    expected_log_probs = agent.policy(torch.from_numpy(obs), 1.7).log_prob(torch.from_numpy(actions))
    np.testing.assert_allclose(log_probs, expected_log_probs.detach().numpy(), rtol=1e-5, atol=1e-6)
