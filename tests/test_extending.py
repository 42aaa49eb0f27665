"""A researcher's first changes must work, or stop with one line: a γ_train schedule, an adaptive
γ_train, a bigger actor, a new argument, a goal-conditioned null embedding, acting with a loaded agent."""

import ast
import dataclasses
import io
import os
import re
import shutil
import subprocess
import sys
import tokenize
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch._dynamo.testing
from conftest import ROOT, SCRIPTS, one_line_error, run_main, small_args, train
from torch import nn

import eval_gamma_sweep as sweep
import plot_results
import ppo_pgg_continuous
import ppo_pgg_discrete
from paper_study import paper
from pgg_utils import checkpoints, evaluation, fast, files, identity, runs, scripts
from pgg_utils import sweep as engine
from pgg_utils.arguments import ARGUMENT_RULES, RUN_ONLY_ARGS
from pgg_utils.guidance import ADAPTIVE_STEP, GuidanceSchedule
from pgg_utils.identity import FROZEN_DEFAULTS, GOAL_DIMS

LINEAR = {"guidance": 1.0, "guidance_schedule": "linear", "guidance_final": 1.3, "cond_dropout": 0.0}


def logged(run_dir, tag: str) -> list[float]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
    events.Reload()
    return [e.value for e in events.Scalars(tag)]


def load(run_dir, mark) -> dict:
    return torch.load(checkpoints.checkpoint_path(run_dir, mark), weights_only=True)


# --- the training γ: a schedule with one owner ----------------------------------------------------


def test_a_linear_schedule_from_one_trains_the_null_embedding_and_is_named_for_what_it_is(tmp_path):
    args = small_args("discrete", tmp_path, **LINEAR)
    run_dir = train(ppo_pgg_discrete, args)
    assert run_dir.name == "CartPole-v1__ppo_pgg__g1to1.3__p0__s1"
    # γ_train rises linearly from 1 at the first iteration to 1.3 at the last, as logged
    np.testing.assert_allclose(logged(run_dir, "pgg/guidance"), np.linspace(1.0, 1.3, 6), rtol=1e-6)
    ckpt = load(run_dir, 1536)
    assert ckpt["model"]["null_obs"].abs().sum() > 0  # γ_train = 1 at the start, yet the null branch trains
    variant = identity.variant_id(ckpt["args"])
    assert variant == "pgg_g1to1.3" and paper.paper_name(variant) == "PGG, γ_train 1 → 1.3"
    assert paper.paper_rows(variant) is None
    assert identity.config_label(ckpt) == "pgg_g1to1.3 num_steps=64 total_timesteps=1536"


def test_constant_guidance_one_without_dropout_leaves_the_null_embedding_out(tmp_path):
    ckpt = load(train(ppo_pgg_discrete, small_args("discrete", tmp_path, guidance=1.0, cond_dropout=0.0)), 1536)
    assert torch.equal(ckpt["model"]["null_obs"], torch.zeros(4))
    assert identity.variant_id(ckpt["args"]) == "ppo"


@pytest.mark.parametrize("schedule", ["linear", "adaptive"])
def test_a_scheduled_run_resumes_bit_for_bit_and_refuses_another_schedule(tmp_path, schedule):
    flags = LINEAR if schedule == "linear" else {"guidance": 1.1, "guidance_schedule": "adaptive",
                                                 "guidance_kl_target": 1e-4, "cond_dropout": 0.0}  # fmt: skip
    args = small_args("discrete", tmp_path, **flags, run_name="straight")
    straight = train(ppo_pgg_discrete, args)
    stopped = tmp_path / "stopped"
    stopped.mkdir()
    (stopped / "checkpoints").mkdir()
    for mark in (512, 1024):
        (stopped / "checkpoints" / checkpoints.checkpoint_path(stopped, mark).name).write_bytes(
            checkpoints.checkpoint_path(straight, mark).read_bytes()
        )
    train(ppo_pgg_discrete, replace(args, run_name="stopped", resume=True))
    a, b = load(straight, 1536), load(stopped, 1536)
    assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])
    if schedule == "adaptive":
        assert a["resume"]["guidance"] == b["resume"]["guidance"]
    changed = replace(args, guidance_final=1.2) if schedule == "linear" else replace(args, guidance_kl_target=2e-4)
    with pytest.raises(runs.RunDirError, match="other arguments"):
        train(ppo_pgg_discrete, replace(changed, run_name="stopped", resume=True))


def test_the_adaptive_rule_holds_the_kl_near_its_target_within_bounds():
    args = ppo_pgg_discrete.Args(guidance=1.2, guidance_schedule="adaptive", guidance_kl_target=0.01,
                                 guidance_bounds=(1.0, 1.5))  # fmt: skip
    schedule = GuidanceSchedule(args, 10)
    kl = lambda value: {"pgg/kl_guided_vs_conditional": value}
    schedule.observe(kl(0.01))  # within [target / 1.5, target · 1.5]: held
    assert schedule.value(2) == 1.2
    schedule.observe(kl(0.1))  # too far from the conditional policy: the strength γ - 1 shrinks
    assert schedule.value(3) == pytest.approx(1 + 0.2 / ADAPTIVE_STEP)
    for _ in range(20):
        schedule.observe(kl(0.0))  # guidance changes nothing: the strength grows, up to the bound
    assert schedule.value(4) == 1.5


def test_an_adaptive_run_logs_the_gamma_its_rule_chose(tmp_path):
    args = small_args("discrete", tmp_path, guidance=1.1, guidance_schedule="adaptive", guidance_kl_target=1e-6,
                      cond_dropout=0.0)  # fmt: skip
    run_dir = train(ppo_pgg_discrete, args)
    gammas, kls = logged(run_dir, "pgg/guidance"), logged(run_dir, "pgg/kl_guided_vs_conditional")
    assert gammas[0] == pytest.approx(1.1) and run_dir.name == "CartPole-v1__ppo_pgg__adaptive1.1_kl1e-06__p0__s1"
    for gamma, kl, following in zip(gammas, kls, gammas[1:]):  # each step of the rule, from what was logged
        strength = gamma - 1
        expected = (
            strength / ADAPTIVE_STEP if kl > 1.5e-6 else strength * ADAPTIVE_STEP if kl < 1e-6 / 1.5 else strength
        )
        assert following == pytest.approx(min(max(1 + expected, 1.0), 1.5), rel=1e-6)
    assert identity.variant_id(load(run_dir, 1536)["args"]) == "pgg_adaptive1.1_kl1e-06"


@pytest.mark.parametrize(
    "flags,message",
    [
        (["--guidance-final", "1.2"], "--guidance-final goes with --guidance-schedule linear"),
        (["--guidance-schedule", "linear"], "--guidance-final goes with --guidance-schedule linear"),
        (["--guidance-schedule", "linear", "--guidance-final", "-5"], "--guidance-final must be a number in [0, 1000]"),
        (["--guidance-schedule", "adaptive", "--guidance-kl-target", "0.01"], "needs 1 <= low <= --guidance <= high"),
        (["--guidance-bounds", "1", "2"], "--guidance-bounds goes with --guidance-schedule adaptive"),
    ],
)
def test_guidance_flags_are_checked_in_one_line(tmp_path, flags, message):
    proc = run_main(ppo_pgg_discrete, "--output-dir", str(tmp_path), "--total-timesteps", "512", *flags)
    assert message in one_line_error(proc)
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("module", [ppo_pgg_discrete, ppo_pgg_continuous], ids=["discrete", "continuous"])
def test_a_new_gamma_value_compiles_nothing(module):
    """--compile: γ_train enters the compiled loss as a tensor, so a schedule over 10 values is one graph."""
    torch.manual_seed(0)
    agent, counter = module.Agent(4, 2), torch._dynamo.testing.CompileCounter()
    batch = {"obs": torch.randn(64, 4), "logprobs": torch.randn(64), "advantages": torch.randn(64),
             "returns": torch.randn(64), "values": torch.randn(64),
             "actions": torch.randint(0, 2, (64,)) if module is ppo_pgg_discrete else torch.randn(64, 2)}  # fmt: skip
    compiled = torch.compile(module.minibatch_loss, backend=counter)
    torch._dynamo.reset()
    for gamma in np.linspace(1.0, 1.3, 10):
        compiled(agent, batch, torch.arange(32), None, torch.tensor(gamma, dtype=torch.float32), module.Args())
    assert counter.frame_count == 1


# --- a bigger actor: the numpy copy follows the module, or steps aside ---------------------------


def with_layer_norm(agent, network: str):
    """The researcher's edit: LayerNorm before each Tanh of the actor."""
    old = getattr(agent, network)
    layers = []
    for layer in old:
        if isinstance(layer, nn.Tanh):
            layers.append(nn.LayerNorm(layers[-1].out_features))
        layers.append(layer)
    setattr(agent, network, nn.Sequential(*layers))
    return agent


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_an_actor_with_layer_norm_acts_as_its_module_and_the_first_ratio_is_one(kind, monkeypatch, tmp_path):
    """Rollouts act through the module's own forward where the numpy copy does not know a layer, so
    the rollout's log-probabilities are the update's: on the first minibatch every ratio is 1."""
    module = SCRIPTS[kind]
    network = "actor" if kind == "discrete" else "actor_mean"
    real_agent = module.Agent
    monkeypatch.setattr(module, "Agent", lambda *a, **k: with_layer_norm(real_agent(*a, **k), network))
    first = {}
    real_update = module.ppo_update

    def first_minibatch(agent, optimizer, buf, advantages, returns, args, guidance, loss_fn=module.minibatch_loss):
        if not first:
            batch = {"obs": buf.obs.reshape(-1, buf.obs.shape[-1]), "logprobs": buf.logprobs.reshape(-1),
                     "actions": buf.actions.reshape(-1, *buf.actions.shape[2:]), "advantages": advantages.reshape(-1),
                     "returns": returns.reshape(-1), "values": buf.values.reshape(-1)}  # fmt: skip
            first.update(module.minibatch_loss(agent, batch, torch.arange(64), None, guidance, args)[1])
        return real_update(agent, optimizer, buf, advantages, returns, args, guidance, loss_fn)

    monkeypatch.setattr(module, "ppo_update", first_minibatch)
    run_dir = train(module, small_args(kind, tmp_path, guidance=1.3, cond_dropout=0.0))
    assert first["losses/clipfrac"].item() == 0.0 and abs(first["losses/approx_kl"].item()) < 1e-6
    # the sweep acts through the same module: its deterministic action is the module's guided output
    agent, ckpt = evaluation.load_any_checkpoint(checkpoints.checkpoints_of(run_dir)[-1])
    assert any(isinstance(m, nn.LayerNorm) for m in getattr(agent, network))
    raw = np.random.default_rng(0).normal(size=(8, ckpt["obs_dim"]))
    with torch.no_grad():
        if kind == "discrete":
            expected = agent.policy(torch.as_tensor(raw, dtype=torch.float32), 1.3).mode().numpy()
        else:
            expected = agent.policy(agent.obs_norm(raw), 1.3).mode().clamp(-0.4, 0.4).numpy()
    policy = evaluation.GuidedPolicy(agent, ckpt)
    actions = policy.act(raw, np.full(8, 1.3), None, deterministic=True)
    np.testing.assert_allclose(actions, expected, rtol=1e-5, atol=1e-6)


def test_the_numpy_copy_is_checked_against_its_module(monkeypatch):
    actor = ppo_pgg_discrete.Agent(4, 2).actor
    fast.numpy_network(actor)  # the copy of Linear and Tanh holds
    monkeypatch.setitem(fast.NUMPY_ACTIVATIONS, nn.Tanh, lambda x: x)  # a copy that treats Tanh wrongly
    with pytest.raises(ValueError, match=r"numpy copy of the network \(Linear, Tanh, Linear, Tanh, Linear\) disagrees"):
        fast.numpy_network(actor)


# --- an argument is one change -------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_every_training_argument_has_a_rule_and_the_scripts_defaults_are_cleanrls(kind):
    """A new field of Args needs a rule in pgg_utils/arguments.py's ARGUMENT_RULES (this test says which is
    missing), and the two scripts' defaults are the frozen ones labels are written against (CleanRL's),
    so that the committed tables keep their labels; a fork's new argument needs neither table to be kept apart."""
    training = {f.name for f in dataclasses.fields(SCRIPTS[kind].Args)} - RUN_ONLY_ARGS - {"env_id", "seed"}
    assert not training - ARGUMENT_RULES.keys(), "add to ARGUMENT_RULES"
    defaults = dataclasses.asdict(SCRIPTS[kind].Args())
    assert {name: defaults[name] for name in training} == FROZEN_DEFAULTS[kind]
    for name in training:  # today's defaults pass their own rule
        assert ARGUMENT_RULES[name][0](defaults[name]), name


# --- guidance on a goal --------------------------------------------------------------------------


def test_a_goal_null_embedding_replaces_only_the_goal_dimensions():
    agent = ppo_pgg_continuous.Agent(11, 2, null_dims=GOAL_DIMS["Reacher-v4"])
    with torch.no_grad():
        agent.null_obs.fill_(7.0)
    obs = torch.randn(5, 11)
    nulled = agent.null_input(obs)
    goal = list(GOAL_DIMS["Reacher-v4"])
    rest = [d for d in range(11) if d not in goal]
    assert (nulled[:, goal] == 7.0).all() and torch.equal(nulled[:, rest], obs[:, rest])
    np.testing.assert_array_equal(agent.null_input(obs.numpy()), nulled.detach().numpy())
    with torch.no_grad():  # the rollouts' numpy policy and the update's torch one agree
        policy = ppo_pgg_continuous.FastPolicy(agent, 1.5)
        noise = np.zeros((5, 2), np.float32)
        actions, _, _ = policy.act(obs.numpy(), noise)
        torch.testing.assert_close(torch.from_numpy(actions), agent.policy(obs, 1.5).mean, rtol=1e-5, atol=1e-6)
    args = {**FROZEN_DEFAULTS["continuous"], "env_id": "Reacher-v4", "guidance": 1.1, "null_dims": goal}
    assert identity.variant_id(args) == "pgg_g1.1_goal"
    assert identity.variant_id({**args, "null_dims": [4, 5]}) == "pgg_g1.1_null4-5"
    assert identity.variant_id({**args, "guidance": 1.0}) == "ppo"  # without guidance the null is unused


def test_goal_dimensions_outside_the_observation_are_refused(tmp_path):
    proc = run_main(ppo_pgg_continuous, "--env-id", "Reacher-v4", "--guidance", "1.1", "--null-dims", "4", "11",
                    "--output-dir", str(tmp_path))  # fmt: skip
    assert one_line_error(proc) == "error: --null-dims must be observation indices of Reacher-v4, 0..10, got [4, 11]"


# --- act from a loaded agent ---------------------------------------------------------------------


def test_act_from_a_loaded_agent_is_the_sweeps_policy(tmp_path):
    run_dir = train(ppo_pgg_continuous, small_args("continuous", tmp_path))
    agent, ckpt = ppo_pgg_continuous.load_checkpoint(checkpoints.checkpoints_of(run_dir)[-1])
    import gymnasium as gym

    env = gym.make(ckpt["env_id"])
    raw, _ = env.reset(seed=0)
    mean = agent.act(raw, guidance=1.2, deterministic=True)
    assert mean.shape == env.action_space.shape and np.abs(mean).max() <= 0.4  # Humanoid's bounds
    noise = np.random.default_rng(0).standard_normal((1, mean.shape[0])).astype(np.float32)
    policy = evaluation.GuidedPolicy(agent, ckpt)
    np.testing.assert_array_equal(agent.act(raw[None], 1.2, noise=noise), policy.act(raw[None], np.array([1.2]), noise,
                                                                                    False))  # fmt: skip
    torch.manual_seed(0)
    sampled = agent.act(raw, guidance=1.2)
    torch.manual_seed(0)
    assert np.array_equal(sampled, agent.act(raw, guidance=1.2)) and not np.array_equal(sampled, mean)


def test_a_linear_schedule_that_does_not_move_is_refused(tmp_path):
    proc = run_main(ppo_pgg_discrete, "--output-dir", str(tmp_path), "--guidance-schedule", "linear",
                    "--guidance-final", "1")  # fmt: skip
    assert "needs a --guidance-final other than --guidance (else: constant)" in one_line_error(proc)


def test_the_numpy_copy_steps_aside_for_a_network_it_does_not_know():
    """A layer it does not know (or a subclass of one it knows) sends the network through its module:
    the rollout acts as the module does, and nothing is probed that could draw random numbers."""

    class ScaledLinear(nn.Linear):
        def forward(self, x):
            return 2 * super().forward(x)

    for network in (nn.Sequential(nn.Linear(4, 8), nn.Dropout(0.5), nn.Tanh(), nn.Linear(8, 2)),
                    nn.Sequential(ScaledLinear(4, 8), nn.Tanh(), nn.Linear(8, 2))):  # fmt: skip
        network.eval()
        x = np.random.default_rng(0).standard_normal((5, 4)).astype(np.float32)
        state = torch.get_rng_state()
        forward = fast.numpy_network(network)
        assert torch.equal(torch.get_rng_state(), state)
        with torch.no_grad():
            np.testing.assert_array_equal(forward(x), network(torch.from_numpy(x)).numpy())


def test_a_checkpoint_with_clip_actions_infinite_bounds_acts_within_the_tasks(tmp_path):
    run_dir = train(ppo_pgg_continuous, small_args("continuous", tmp_path))
    ckpt = load(run_dir, 768)
    old = {**ckpt, "action_low": [float("-inf")] * 17, "action_high": [float("inf")] * 17}  # as saved before
    agent = ppo_pgg_continuous.agent_from_checkpoint(old)
    np.testing.assert_array_equal(agent.action_bounds[1], np.full(17, 0.4, np.float32))  # Humanoid's own
    assert np.abs(agent.act(np.zeros(ckpt["obs_dim"]), guidance=50.0, noise=np.full((1, 17), 9.0))).max() == 0.4


# --- the `# PGG` marks ---------------------------------------------------------------------------

# Names and strings that only PGG's lines use: the null branch, the guidance, conditioning dropout and
# its kept rows, the γ schedule, and the "pgg/" statistics.
PGG_CONCEPT = re.compile(r"null|guid|uncond|drop|kept|schedule|pgg", re.IGNORECASE)


def pgg_lines(source: str) -> set[int]:
    """The code lines of a training script that PGG adds to PPO or changes, by rule: a line whose code
    (names and strings; not comments, not docstrings) names a PGG concept; every line of a function
    whose name does (decorators included); every line of a statement whose first line is PGG (a dict
    of PGG statistics, closing bracket included); and the header of a block whose body is all PGG (a
    `with torch.no_grad():` around the null branch). What it cannot see: a change to PPO made in a line
    that names no PGG concept (a flipped clip: tests/test_discrete.py and test_continuous.py hold the loss
    to CleanRL's), a PGG line under a name outside PGG_CONCEPT, and docstrings, which are exempt."""
    tree = ast.parse(source)
    docstrings = {
        line
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)
        for line in range(node.lineno, node.end_lineno + 1)
    }
    code = defaultdict(str)  # code line -> its names and strings
    layout = (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER)
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type not in layout and token.start[0] not in docstrings:
            named = token.type in (tokenize.NAME, tokenize.STRING)
            code[token.start[0]] += " " + token.string.replace("pgg_utils", "") if named else ""
    lines = {line for line, text in code.items() if PGG_CONCEPT.search(text)}

    def code_lines(first: int, last: int) -> set[int]:
        return {line for line in range(first, last + 1) if line in code}

    statements = sorted((node for node in ast.walk(tree) if isinstance(node, ast.stmt)), key=lambda n: -n.lineno)
    for node in statements:  # innermost first, so a block's body is settled before its header
        first = min([node.lineno, *(d.lineno for d in getattr(node, "decorator_list", []))])
        body = getattr(node, "body", None)
        if (
            isinstance(node, (ast.FunctionDef, ast.ClassDef))
            and PGG_CONCEPT.search(node.name)
            or body is None
            and first in lines
        ):
            lines |= code_lines(first, node.end_lineno)
        elif body and not isinstance(node, ast.ClassDef):
            block = code_lines(body[0].lineno, node.end_lineno)
            if block and block <= lines:
                lines |= code_lines(first, body[0].lineno - 1)
    return lines


def marked_lines(source: str) -> set[int]:
    return {
        token.start[0]
        for token in tokenize.generate_tokens(io.StringIO(source).readline)
        if token.type == tokenize.COMMENT and re.match(r"# PGG\b", token.string)
    }


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_pgg_marks_exactly_the_lines_pgg_adds_to_ppo(kind):
    """`# PGG` marks every line of a training script that PGG adds to or changes in PPO, and nothing else
    (pgg_lines is the rule), so that a reader, or a fork, sees PGG's algorithm at a glance."""
    path = Path(SCRIPTS[kind].__file__)
    source = path.read_text()
    text = source.splitlines()
    required, marked = pgg_lines(source), marked_lines(source)
    unmarked = [f"{path.name}:{line}: {text[line - 1].strip()}" for line in sorted(required - marked)]
    false_marks = [f"{path.name}:{line}: {text[line - 1].strip()}" for line in sorted(marked - required)]
    assert not unmarked and not false_marks, "\n".join(
        ["PGG lines without `# PGG`:", *unmarked, "`# PGG` on lines of PPO's own:", *false_marks]
    )


# --- one guided mix, one Gumbel sampler ----------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_rollouts_and_act_mix_the_two_branches_through_guide_alone(kind, monkeypatch):
    """`guide` is the one function that mixes (1-γ)·null + γ·cond, for the rollouts and for `act` (the
    sweep's); one guidance per row mixes each row exactly as that row's own number does."""
    module, real_guide = SCRIPTS[kind], SCRIPTS[kind].guide
    torch.manual_seed(0)
    agent = module.Agent(4, 3)
    mixed = []
    monkeypatch.setattr(module, "guide", lambda cond, *rest: mixed.append(type(cond)) or real_guide(cond, *rest))
    rng = np.random.default_rng(0)
    obs, noise = rng.normal(size=(5, 4)).astype(np.float32), rng.normal(size=(5, 3)).astype(np.float32)
    module.FastPolicy(agent, 1.3).act(obs, noise)
    agent.act(obs, np.linspace(0.0, 3.0, 5), deterministic=True)
    assert mixed == [np.ndarray, np.ndarray]
    cond, null, per_row = (
        rng.normal(size=(5, 3)).astype(np.float32),
        rng.normal(size=3).astype(np.float32),
        rng.random(5) * 3,
    )
    rows = real_guide(cond, null, per_row)
    assert rows.dtype == np.float32
    for i, guidance in enumerate(per_row):
        assert np.array_equal(rows[i], real_guide(cond[i : i + 1], null, float(guidance))[0])


def test_training_and_the_sweep_sample_gumbel_noise_through_one_function():
    torch.manual_seed(3)
    noise = ppo_pgg_discrete.gumbel_noise(6, 4)
    torch.manual_seed(3)
    assert noise.dtype == np.float32 and np.array_equal(noise, fast.standard_gumbel(torch.rand(6, 4).numpy()))
    uniform = np.random.default_rng([10_000 + 2, 1]).uniform(np.finfo(np.float32).tiny, 1.0, size=(50, 4))
    expected = fast.standard_gumbel(uniform).astype(np.float32)
    assert np.array_equal(evaluation.episode_noise("discrete", 10_000, 2, 50, 4), expected)
    assert np.isfinite(fast.standard_gumbel(np.zeros(3, np.float32))).all()  # a uniform draw of 0 stays finite


# --- act and load_checkpoint refuse what training refuses ----------------------------------------


def fresh_checkpoint(kind: str) -> dict:
    """The checkpoint dict of an untrained agent with 4 observation dimensions and 3 actions."""
    torch.manual_seed(0)
    if kind == "discrete":
        shapes = {"obs_dim": 4, "n_actions": 3}
    else:
        shapes = {"obs_dim": 4, "action_dim": 3, "action_low": [-1.0] * 3, "action_high": [1.0] * 3}
    args = {"obs_clip": 10.0} if kind == "continuous" else {}
    model = SCRIPTS[kind].make_agent(args, shapes).state_dict()
    return {
        "format_version": checkpoints.CHECKPOINT_FORMAT_VERSION,
        "action_space": kind,
        "args": args,
        "model": model,
        **shapes,
    }


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
@pytest.mark.parametrize("guidance", [float("nan"), -5.0, 1e6, float("inf"), -0.001, [1.0, float("nan")], [2.0, 1001]])
def test_act_refuses_a_guidance_that_training_and_the_sweep_refuse(kind, guidance):
    agent = SCRIPTS[kind].agent_from_checkpoint(fresh_checkpoint(kind))
    worst = np.asarray(guidance, dtype=np.float64)
    worst = worst.min() if np.isnan(worst).any() or worst.min() < 0 else worst.max()
    with pytest.raises(ValueError) as refused:
        agent.act(np.zeros((2, 4)), guidance)
    assert str(refused.value) == f"guidance must be a number in [0, 1000], got {float(worst)!r}"


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_refuses_a_non_finite_observation_and_guidance_of_another_length(kind):
    agent = SCRIPTS[kind].agent_from_checkpoint(fresh_checkpoint(kind))
    for bad in (np.nan, np.inf, -np.inf):
        for obs in (np.array([0.0, bad, 0.0, 0.0]), np.array([[0.0] * 4, [0.0, 0.0, 0.0, bad]])):
            with pytest.raises(ValueError, match=r"^the observation holds a NaN or an infinity$"):
                agent.act(obs, 1.0)
    with pytest.raises(
        ValueError, match=r"^guidance must be a number or one per observation \(2\), got an array of shape \(3,\)$"
    ):
        agent.act(np.zeros((2, 4)), [1.0, 1.0, 1.0])
    for guidance in (0.0, 1000.0, [0.0, 1000.0]):  # the rule's bounds are inside it
        assert np.isfinite(np.asarray(agent.act(np.zeros((2, 4)), guidance), dtype=np.float64)).all()
    assert np.asarray(agent.act(np.zeros(4), np.array([1.2]), deterministic=True)).shape == (
        () if kind == "discrete" else (3,)
    )


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_load_checkpoint_refuses_non_finite_weights(kind, tmp_path):
    ckpt = fresh_checkpoint(kind)
    torch.save(ckpt, tmp_path / "finite.pt")
    SCRIPTS[kind].load_checkpoint(tmp_path / "finite.pt")
    ckpt["model"]["critic.0.weight"][0, 0] = float("nan")
    torch.save(ckpt, tmp_path / "diverged.pt")
    with pytest.raises(ValueError) as refused:
        SCRIPTS[kind].load_checkpoint(tmp_path / "diverged.pt")
    assert (
        str(refused.value)
        == f"{tmp_path / 'diverged.pt'} holds non-finite weights or statistics (critic.0.weight); not loaded"
    )


# --- a fork: a copied script is evaluated by its own code and kept apart -----------------------------

# A researcher's first-week fork of the continuous script: ReLU in place of Tanh, and a new argument
# whose loss term reads the unconditional branch (it pulls the unconditional mean toward 0.5).
FORK_FIELD_ANCHOR = '    """normalised rewards are clipped to [-reward_clip, reward_clip]"""\n'
FORK_FIELD = (
    '    null_mean_coef: float = 0.0\n    """pull the unconditional mean toward 0.5 (a fork\'s new loss term)"""\n'
)
FORK_LOSS_ANCHOR = "    loss = pg_loss - args.ent_coef * entropy_loss + v_loss * args.vf_coef\n"
FORK_LOSS = "    if args.null_mean_coef:\n        loss = loss + args.null_mean_coef * (agent.unconditional_mean() - 0.5).square().sum()\n"


def write_fork(folder: Path, name: str = "ppo_pgg_relu.py") -> Path:
    source = (ROOT / "ppo_pgg_continuous.py").read_text()
    assert source.count("nn.Tanh()") == 4 and FORK_FIELD_ANCHOR in source and FORK_LOSS_ANCHOR in source
    source = source.replace("nn.Tanh()", "nn.ReLU()").replace(FORK_FIELD_ANCHOR, FORK_FIELD_ANCHOR + FORK_FIELD)
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(source.replace(FORK_LOSS_ANCHOR, FORK_LOSS_ANCHOR + FORK_LOSS))
    return path


def train_script(path: Path, tmp_path, run_name: str, **overrides) -> Path:
    """Trains a tiny continuous run with the training script at `path`, in this process."""
    module = scripts.load_module(path)
    base = dataclasses.asdict(small_args("continuous", tmp_path / "runs", run_name=run_name))
    return runs.train_in_process(module, module.Args(**{**base, **overrides}))


def sweep_rows(tmp_path, name: str, *given: Path, **overrides) -> list[dict]:
    args = sweep.Args(paths=(str(tmp_path / "runs"),), output=str(tmp_path / name), gammas=(1.0, 1.5), episodes=3,
                      steps=(768,), deterministic=True, script=tuple(map(str, given)), **overrides)  # fmt: skip
    sweep.sweep(args)
    return files.read_csv(tmp_path / name / "episodes.csv")


@pytest.mark.slow
def test_a_relu_fork_is_swept_with_its_own_agent_and_never_pooled_with_the_original(tmp_path, capsys):
    fork = write_fork(tmp_path / "elsewhere")
    fork_run = train_script(fork, tmp_path, "fork_s1", seed=1)
    train_script(ROOT / "ppo_pgg_continuous.py", tmp_path, "tanh_s2", seed=2)
    # A fork outside the repository is evaluated only where the user names it: one line, the rest swept.
    rows = sweep_rows(tmp_path, "unnamed")
    assert {row["run"] for row in rows} == {"tanh_s2"}
    assert f"pass --script {fork}" in files.read_csv(tmp_path / "unnamed" / "skipped.csv")[0]["reason"]
    rows = sweep_rows(tmp_path, "named", fork)
    configs = {row["run"]: row["config"] for row in rows}
    tanh = "pgg_g1.1_drop0.1 num_minibatches=4 num_steps=256 total_timesteps=768 update_epochs=2 mujoco=2.3.7"
    assert configs["tanh_s2"] == tanh
    # The fork's label names its script and its new argument, at whatever value (here the default).
    assert configs["fork_s1"] == tanh.replace("drop0.1", f"drop0.1 script={fork} null_mean_coef=0.0")
    assert len(files.read_csv(tmp_path / "named" / "summary.csv")) == 4  # two configurations x two γ, never pooled
    (evaluated,) = [r for r in files.read_csv(tmp_path / "named" / "evaluated_by.csv") if r["run"] == "fork_s1"]
    assert evaluated["evaluated_by"] == str(fork) and evaluated["same_script"] == "yes"
    # The sweep's episodes are the fork's own Agent.act, not the original Agent's with the fork's weights.
    fork_module = scripts.load_module(fork)
    agent, ckpt = fork_module.load_checkpoint(checkpoints.checkpoint_path(fork_run, 768))
    original = ppo_pgg_continuous.make_agent(ckpt["args"], ckpt)
    original.load_state_dict(ckpt["model"])
    for gamma in (1.0, 1.5):
        swept = [float(r["return"]) for r in rows if r["run"] == "fork_s1" and float(r["eval_guidance"]) == gamma]
        own = evaluation.evaluate_cell(evaluation.GuidedPolicy(agent, ckpt), ckpt, gamma, 3, 10_000, True)["return"]
        tanh = evaluation.evaluate_cell(evaluation.GuidedPolicy(original.eval(), ckpt), ckpt, gamma, 3, 10_000, True)[
            "return"
        ]
        assert swept == own.tolist() and swept != tanh.tolist()
    # The original script's loader refuses the fork's checkpoint in one line.
    with pytest.raises(ValueError, match="was trained by .*ppo_pgg_relu.py, not ppo_pgg_continuous.py"):
        ppo_pgg_continuous.load_checkpoint(checkpoints.checkpoint_path(fork_run, 768))


@pytest.mark.slow
def test_a_forks_new_argument_splits_configurations_and_trains_the_null_branch_under_guidance_one(tmp_path):
    fork = write_fork(tmp_path / "elsewhere")
    plain = {"guidance": 1.0, "cond_dropout": 0.0}
    pulled = load(train_script(fork, tmp_path, "pulled_s1", seed=1, null_mean_coef=0.5, **plain), 768)
    default = load(train_script(fork, tmp_path, "default_s2", seed=2, **plain), 768)
    # The loss reads the null branch: it trains at γ_train 1, no dropout. At the default it is PPO's run.
    assert pulled["model"]["null_obs"].abs().sum() > 0 and not default["model"]["null_obs"].any()
    ppo = load(train_script(ROOT / "ppo_pgg_continuous.py", tmp_path, "ppo_s2", seed=2, **plain), 768)
    assert not torch.equal(default["model"]["actor_mean.0.weight"], ppo["model"]["actor_mean.0.weight"])  # ReLU
    rows = sweep_rows(tmp_path, "sweep", fork)
    configs = {row["run"]: row["config"] for row in rows}
    assert "null_mean_coef=0.5" in configs["pulled_s1"] and "null_mean_coef=0.0" in configs["default_s2"]
    assert len(set(configs.values())) == 3
    summary = files.read_csv(tmp_path / "sweep" / "summary.csv")
    assert {row["n_seeds"] for row in summary} == {"1"} and len(summary) == 6
    # The tables and the learning curves keep the same three configurations apart, under one set of names.
    series = {row["series"] for row in plot_results.summarise(plot_results.read_episodes([str(tmp_path / "sweep")]))}
    curves, left_out = plot_results.training_curves([str(tmp_path / "runs")])
    assert not left_out and {label for _, _, label in curves} == series and len(series) == 3


@pytest.mark.slow
def test_an_edited_script_or_task_is_evaluated_again_never_read_from_the_cache(tmp_path, monkeypatch):
    fork = write_fork(tmp_path / "elsewhere", "ppo_pgg_continuous.py")  # a copy of the original, as edited in place
    train_script(fork, tmp_path, "run_s1", seed=1)
    first = sweep_rows(tmp_path, "sweep", fork)
    evaluated = []
    real_run_job = engine.run_job
    monkeypatch.setattr(engine, "run_job", lambda job: evaluated.append(job) or real_run_job(job))
    assert sweep_rows(tmp_path, "sweep", fork) == first and not evaluated  # unchanged: every cell reused
    fork.write_text(fork.read_text().replace("nn.ReLU()", "nn.Tanh()"))  # the Agent edited after the sweep
    scripts.load_module.cache_clear()
    again = sweep_rows(tmp_path, "sweep", fork)
    assert len(evaluated) == 2 and again != first
    (record,) = files.read_csv(tmp_path / "sweep" / "evaluated_by.csv")
    assert record["same_script"] == "no"


TASK_MODULE = """
import gymnasium as gym
import numpy as np


class Drift(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.np_random.normal(size=3).astype(np.float32), {}

    def step(self, action):
        self.t += 1
        reward = REWARD * float(action[0])
        return self.np_random.normal(size=3).astype(np.float32), reward, False, self.t >= 20, {}


gym.register("ForkDrift-v0", entry_point=Drift, max_episode_steps=20)
"""


def test_a_custom_tasks_edit_is_evaluated_again(tmp_path, monkeypatch):
    module = tmp_path / "tasks" / "fork_drift_task.py"
    module.parent.mkdir()
    module.write_text("REWARD = 1.0\n" + TASK_MODULE)
    monkeypatch.syspath_prepend(str(module.parent))
    env_id = "fork_drift_task:ForkDrift-v0"
    train_script(ROOT / "ppo_pgg_continuous.py", tmp_path, "drift_s1", env_id=env_id)
    first = sweep_rows(tmp_path, "sweep")
    module.write_text("REWARD = -1.0\n" + TASK_MODULE)  # the task's module edited after the sweep
    for name in [m for m in sys.modules if m == "fork_drift_task"]:
        del sys.modules[name]
    gym.registry.pop("ForkDrift-v0")
    again = sweep_rows(tmp_path, "sweep")
    assert [-float(r["return"]) for r in again] == [float(r["return"]) for r in first]


# --- training stands apart from the paper study ---------------------------------------------------

# Runs a script with the paper study unimportable: an import of it is an ImportError naming it.
WITHOUT_THE_PAPER_STUDY = """
import runpy, sys
class PaperStudy:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {"paper_study", "plot_results", "reproduce", "matplotlib"}:
            raise ImportError(f"{name} belongs to the paper study")
sys.meta_path.insert(0, PaperStudy())
sys.argv = sys.argv[1:]
if sys.argv[0] == "-c":
    exec(sys.argv[1])
else:
    runpy.run_path(sys.argv[0], run_name="__main__")
"""


@pytest.mark.slow
def test_training_the_sweep_and_act_work_in_a_copy_without_the_paper_study(tmp_path):
    core = tmp_path / "core"
    shutil.copytree(ROOT / "pgg_utils", core / "pgg_utils", ignore=shutil.ignore_patterns("__pycache__"))
    for script in ("ppo_pgg_discrete.py", "eval_gamma_sweep.py"):
        shutil.copy(ROOT / script, core / script)
    (core / "run.py").write_text(WITHOUT_THE_PAPER_STUDY)

    def run(*command: str) -> str:
        proc = subprocess.run([sys.executable, "run.py", *command], cwd=core, capture_output=True, text=True,
                              timeout=300)  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]
        return proc.stdout

    run("ppo_pgg_discrete.py", "--guidance", "1.1", "--total-timesteps", "512", "--num-steps", "64",
        "--checkpoint-interval", "512", "--output-dir", "runs", "--run-name", "cartpole")  # fmt: skip
    run("eval_gamma_sweep.py", "runs", "--gammas", "1", "2", "--episodes", "2", "--output", "sweep")
    assert len(files.read_csv(core / "sweep" / "episodes.csv")) == 4
    (evaluated,) = files.read_csv(core / "sweep" / "evaluated_by.csv")
    assert evaluated["evaluated_by"] == "ppo_pgg_discrete.py" and evaluated["same_script"] == "yes"
    acted = run("-c", "import numpy as np; from ppo_pgg_discrete import load_checkpoint; "
                "agent, _ = load_checkpoint('runs/cartpole/checkpoints/step_000000512.pt'); "
                "print(agent.act(np.zeros(4), guidance=1.5, deterministic=True))")  # fmt: skip
    assert acted.strip() in ("0", "1")


@pytest.mark.slow
def test_a_script_copied_outside_the_repository_trains_with_the_installed_project_and_sweeps_with_itself(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(ROOT / "ppo_pgg_discrete.py", outside / "my_ppo.py")
    environment = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}  # the installed project
    train = subprocess.run([sys.executable, "my_ppo.py", "--total-timesteps", "512", "--num-steps", "64",
                            "--checkpoint-interval", "512", "--run-name", "mine"], cwd=outside, env=environment,
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert train.returncode == 0, train.stderr[-3000:]
    sweep_command = [sys.executable, str(ROOT / "eval_gamma_sweep.py"), "runs", "--gammas", "1", "--episodes", "2"]
    refused = subprocess.run([*sweep_command, "--output", "refused"], cwd=outside, capture_output=True, text=True,
                             timeout=300)  # fmt: skip
    assert refused.returncode == 2 and f"pass --script {outside / 'my_ppo.py'}" in refused.stderr
    swept = subprocess.run([*sweep_command, "--output", "swept", "--script", "my_ppo.py"], cwd=outside,
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert swept.returncode == 0, swept.stderr[-3000:]
    (evaluated,) = files.read_csv(outside / "swept" / "evaluated_by.csv")
    assert evaluated["evaluated_by"] == str(outside / "my_ppo.py") and evaluated["same_script"] == "yes"
    assert f"script={outside / 'my_ppo.py'}" in files.read_csv(outside / "swept" / "summary.csv")[0]["config"]


# --- behaviour cloning by the null branch while training ------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_behaviour_cloning_by_the_null_branch_trains_it_at_guidance_one_and_routes_its_gradient(kind, tmp_path):
    module = SCRIPTS[kind]
    args = small_args(kind, tmp_path, guidance=1.0, cond_dropout=0.0, null_bc_coef=0.5)
    run_dir = train(module, args)
    ckpt = load(run_dir, args.total_timesteps)
    assert ckpt["model"]["null_obs"].abs().sum() > 0  # the loss reads the null branch: it trains at γ_train 1
    assert run_dir.name.endswith("__bc0.5__s1") and identity.variant_id(ckpt["args"]) == "pgg_bc0.5"
    agent = module.agent_from_checkpoint(ckpt)
    agent.train()
    obs = torch.randn(16, ckpt["obs_dim"])
    if kind == "discrete":
        actions = torch.randint(0, ckpt["n_actions"], (16,))
        term = lambda route: module.null_bc_loss(agent, actions, route)
        actor = agent.actor
    else:
        actions = torch.randn(16, ckpt["action_dim"])
        term = lambda route: module.null_bc_loss(agent, obs, actions, route)
        actor = agent.actor_mean
    for route, actor_learns in (("null", False), ("actor", True)):
        agent.zero_grad(set_to_none=True)
        term(route).backward()
        assert agent.null_obs.grad.abs().sum() > 0
        moved = [p.grad is not None and p.grad.abs().sum() > 0 for p in actor.parameters()]
        assert all(moved) if actor_learns else not any(moved)
        assert agent.actor_logstd.grad is None if kind == "continuous" else True  # the policy's σ is not cloned


def test_a_checkpoint_alone_names_no_file_outside_the_repositorys_top_level(tmp_path):
    """A checkpoint is data: a recorded script with a folder in it (`../x.py`, `runs/x.py`), or one that is
    no file at the repository's top level, is refused in one line, and nothing is imported."""
    outside = tmp_path / "payload.py"
    outside.write_text("raise SystemExit('imported')\n")
    relative = str(Path("..") / outside.relative_to("/")) if outside.is_absolute() else str(outside)
    for recorded in (str(outside), relative, "runs/payload.py", "payload.py", "../" * 12 + str(outside)[1:]):
        with pytest.raises(scripts.ScriptError) as refused:
            scripts.training_module({"action_space": "continuous", "script_path": recorded})
        assert "--script" in str(refused.value) and "\n" not in str(refused.value)
    # Named by the user, the same file is that user's choice: imported, and refused as no training script.
    with pytest.raises(scripts.ScriptError, match="cannot import .*payload.py"):
        scripts.training_module({"action_space": "continuous", "script_path": str(outside)}, (outside,))
