"""What several test modules share: the path to the scripts, one-thread torch, and the helpers that
train a tiny run and run a script as a user would."""

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
from pgg_utils import runs

SCRIPTS = {"discrete": ppo_pgg_discrete, "continuous": ppo_pgg_continuous}


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
    """Runs one of the repository's scripts (e.g. "ppo_pgg_discrete.py") as a command."""
    return subprocess.run(
        [sys.executable, str(ROOT / script), *flags], capture_output=True, text=True, timeout=300, **kwargs
    )


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
