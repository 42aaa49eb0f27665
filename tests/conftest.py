"""What several test modules share: the path to the scripts, one-thread torch, and the helpers that
train a tiny run and run a script as a user would."""

import contextlib
import io
import os
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
torch.set_num_threads(1)

import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import runs, tasks

SCRIPTS = {"discrete": ppo_pgg_discrete, "continuous": ppo_pgg_continuous}


def training_vector_env(module, env_id: str, num_envs: int, seed: int):
    """The vector env `module`'s train makes, at the default discount and reward clip."""
    wrap = (lambda env: module.training_env(env, 0.99, 10.0)) if module is ppo_pgg_continuous else None
    return tasks.make_vector_env(module.make_env, env_id, num_envs, seed, wrap=wrap)


def small_args(kind: str, tmp_path, **overrides):
    """A run of a few iterations with a checkpoint every few: discrete CartPole, continuous Humanoid
    (the task whose observation and reward read quantities MuJoCo derives a step late)."""
    base = {
        "discrete": {"total_timesteps": 1536, "checkpoint_interval": 512, "num_steps": 64},
        "continuous": {"env_id": "Humanoid-v4", "total_timesteps": 768, "checkpoint_interval": 256, "num_steps": 256,
                           "num_minibatches": 4, "update_epochs": 2},
    }[kind]  # fmt: skip
    return replace(SCRIPTS[kind].Args(output_dir=str(tmp_path), guidance=1.1, cond_dropout=0.1, **base), **overrides)


def train(module, args) -> Path:
    """Trains `args` in this process with a training script's module; returns the run directory."""
    return runs.train_in_process(module, args)


def run_script(script: str, *flags, **kwargs) -> subprocess.CompletedProcess:
    """Runs one of the repository's scripts as a user would: a top-level one by its path ("ppo_pgg_discrete.py"), a
    tool of a package as a module ("beyond/command_tracking.py": `python -m beyond.command_tracking`)."""
    path = Path(script)
    command = [str(ROOT / script)]
    if len(path.parts) > 1:
        command = ["-m", ".".join(path.with_suffix("").parts)]
        kwargs["env"] = {**kwargs.get("env", os.environ), "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *command, *flags], capture_output=True, text=True, timeout=300, **kwargs)


def run_main(module, *flags, cwd=None) -> subprocess.CompletedProcess:
    """`python <module>.py *flags` without a new Python: the module's `main()` in this process, with
    sys.argv set, stdout and stderr captured and `cwd` the working directory for the call; its exit
    status, stdout and stderr as run_script's. Cheaper by a Python and torch start-up (~2 s) per call, for
    the many argument and input errors; an exception that escapes `main()` (a traceback, in a command)
    propagates and fails the test. Whatever `main()` sets on the process (signal handlers, sys.argv, the
    working directory, torch's threads) is put back. Which tests still start a real process: those of the entry point
    itself (`if __name__ == "__main__"`), of environment variables, signals and terminals."""
    out, err = io.StringIO(), io.StringIO()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    argv, here, threads, code = sys.argv, os.getcwd(), torch.get_num_threads(), 0
    command = sys.argv = [module.__file__, *map(str, flags)]
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                module.main()
            except SystemExit as e:
                if isinstance(e.code, str):  # sys.exit("message"): Python prints it and exits 1
                    print(e.code, file=sys.stderr)
                code = 1 if isinstance(e.code, str) else (e.code or 0)
    finally:
        sys.argv = argv
        os.chdir(here)
        torch.set_num_threads(threads)  # --torch-threads
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    return subprocess.CompletedProcess(command, code, out.getvalue(), err.getvalue())


def default_sigint() -> None:
    """preexec_fn for a child that a test stops with SIGINT, as Ctrl-C in a terminal would: SIGINT at its
    default. A background job of a shell without job control (`nohup pytest &`) starts with SIGINT
    ignored, its children inherit that, and Python then never raises KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def one_line_error(proc: subprocess.CompletedProcess, code: int = 2) -> str:
    """The one line of error, besides gymnasium's expected two-line notice that v4 tasks are old."""
    lines = [
        line
        for line in proc.stderr.strip().splitlines()
        if "DeprecationWarning" not in line and "logger.deprecation(" not in line
    ]
    assert proc.returncode == code and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


@pytest.fixture
def compiled_calls(monkeypatch) -> list:
    """torch.compile still compiles, and each call of what it compiled is recorded in this list."""
    calls, real_compile = [], torch.compile

    def spy_compile(fn):
        compiled = real_compile(fn)

        def counted(*args, **kwargs):
            calls.append(fn)
            return compiled(*args, **kwargs)

        return counted

    monkeypatch.setattr(torch, "compile", spy_compile)
    return calls


def cleanrl_minibatch_loss(newlogprob, entropy, newvalue, batch: dict, mb_inds, args):
    """PPO's loss and statistics on one minibatch, line for line as CleanRL's ppo.py and
    ppo_continuous_action.py write them, from log-probabilities, entropies and values that the caller
    computes with torch.distributions: the reference the training scripts' `minibatch_loss` is held to."""
    logratio = newlogprob - batch["logprobs"][mb_inds]
    ratio = logratio.exp()
    with torch.no_grad():
        old_approx_kl = (-logratio).mean()
        approx_kl = ((ratio - 1) - logratio).mean()
        clipfrac = ((ratio - 1.0).abs() > args.clip_coef).float().mean()
    mb_advantages = batch["advantages"][mb_inds]
    if args.norm_adv:
        mb_advantages = (mb_advantages - mb_advantages.mean()) / (mb_advantages.std() + 1e-8)
    pg_loss1 = -mb_advantages * ratio
    pg_loss2 = -mb_advantages * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
    pg_loss = torch.max(pg_loss1, pg_loss2).mean()
    newvalue = newvalue.view(-1)
    if args.clip_vloss:
        v_loss_unclipped = (newvalue - batch["returns"][mb_inds]) ** 2
        v_clipped = batch["values"][mb_inds] + torch.clamp(
            newvalue - batch["values"][mb_inds], -args.clip_coef, args.clip_coef
        )
        v_loss_clipped = (v_clipped - batch["returns"][mb_inds]) ** 2
        v_loss_max = torch.max(v_loss_unclipped, v_loss_clipped)
        v_loss = 0.5 * v_loss_max.mean()
    else:
        v_loss = 0.5 * ((newvalue - batch["returns"][mb_inds]) ** 2).mean()
    entropy_loss = entropy.mean()
    loss = pg_loss - args.ent_coef * entropy_loss + v_loss * args.vf_coef
    return loss, {
        "losses/value_loss": v_loss,
        "losses/policy_loss": pg_loss,
        "losses/entropy": entropy_loss,
        "losses/old_approx_kl": old_approx_kl,
        "losses/approx_kl": approx_kl,
        "losses/clipfrac": clipfrac,
    }


def assert_minibatch_loss_is_cleanrls(module, agent, batch: dict, mb_inds, args, reference_distribution) -> None:
    """`module.minibatch_loss` without guidance against cleanrl_minibatch_loss, whose log-probabilities
    and entropies come from `reference_distribution(agent, obs)` (a torch.distributions object, CleanRL's
    get_action_and_value): the loss, its statistics and its gradient, to float rounding. The data must
    reach both sides of every clip: some ratios and some values outside the clip range, some inside."""
    results = []
    for side in ("script", "cleanrl"):
        agent.zero_grad()
        if side == "script":
            loss, stats = module.minibatch_loss(agent, batch, mb_inds, None, None, args)
        else:
            obs, actions = batch["obs"][mb_inds], batch["actions"][mb_inds]
            distribution = reference_distribution(agent, obs)
            newlogprob, entropy = distribution.log_prob(actions), distribution.entropy()
            if newlogprob.dim() == 2:  # a Normal's, per action dimension
                newlogprob, entropy = newlogprob.sum(1), entropy.sum(1)
            loss, stats = cleanrl_minibatch_loss(newlogprob, entropy, agent.critic(obs), batch, mb_inds, args)
        loss.backward()
        grads = {name: p.grad.clone() for name, p in agent.named_parameters() if p.grad is not None}
        results.append((loss.detach(), stats, grads))
    (loss, stats, grads), (expected_loss, expected_stats, expected_grads) = results
    assert 0.1 < expected_stats["losses/clipfrac"] < 0.9  # the ratio clip binds on some rows, not all
    with torch.no_grad():
        value_moved = (agent.get_value(batch["obs"][mb_inds]) - batch["values"][mb_inds]).abs()
    assert 0.1 < (value_moved > args.clip_coef).float().mean() < 0.9  # so does the value clip
    torch.testing.assert_close(loss, expected_loss, rtol=1e-5, atol=1e-6)
    for key, value in expected_stats.items():
        torch.testing.assert_close(stats[key], value, rtol=1e-5, atol=1e-6, msg=key)
    assert grads.keys() == expected_grads.keys() and "null_obs" not in grads  # PPO: the null embedding idle
    for name, grad in expected_grads.items():
        assert grad.abs().max() > 0, name
        torch.testing.assert_close(grads[name], grad, rtol=1e-4, atol=1e-6, msg=name)
