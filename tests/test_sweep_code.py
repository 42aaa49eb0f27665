"""What a cell is computed by: every file of code that runs in its episodes is part of its identity (a copy
of the sweep, a project module that `act` calls), a per-episode column added in a copy of the sweep reaches
episodes.csv, and returns are the task's own whatever the script's make_env adds around the task."""

import importlib.util
import inspect
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT

import eval_gamma_sweep as sweep
import ppo_pgg_discrete
from pgg_utils import cells, episodes, evaluation, files, scripts, video

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "cartpole_format2" / "checkpoints" / "step_000000512.pt"
LOOP_LINE = "actions = policy.act(obs, guidance, noise[t], deterministic)"
RETURN_LINE = '    return {"return": returns, "length": lengths}\n'


def sweep_args(output: Path, **overrides) -> sweep.Args:
    return replace(sweep.Args(paths=(str(FIXTURE),), output=str(output), gammas=(1.0, 2.0), episodes=6), **overrides)


def sweep_copy(tmp_path, name: str, old: str, new: str):
    """A copy of eval_gamma_sweep.py holding its own episode loop, as its docstring's "Changing the episodes" says:
    pgg_utils.evaluation's evaluate_cell copied in below the imports (with `from pgg_utils.evaluation import *`),
    `old` replaced by `new` in it; imported as its own module (as `python name.py` would run it, with this
    repository's pgg_utils)."""
    source, loop = (ROOT / "eval_gamma_sweep.py").read_text(), inspect.getsource(evaluation.evaluate_cell)
    assert loop.count(old) == 1, f"the episode loop no longer holds {old!r}"
    below_imports = "\n\n@dataclass\nclass Args"
    assert source.count(below_imports) == 1
    own_loop = "\nfrom pgg_utils.evaluation import *  # noqa: F403\n\n\n" + loop.replace(old, new)
    path = tmp_path / f"{name}.py"
    path.write_text(source.replace(below_imports, own_loop + below_imports))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses resolve their fields' module through sys.modules
    spec.loader.exec_module(module)
    return module


def cell_files(output: Path) -> set[str]:
    return {path.name for path in (output / "cells").glob("*.csv")}


def test_a_sweep_copy_that_adds_observation_noise_is_not_answered_from_the_originals_cells(tmp_path, capsys):
    output = tmp_path / "out"
    sweep.sweep(sweep_args(output))
    original = files.read_csv(output / "episodes.csv")
    noisy = sweep_copy(tmp_path, "noisy_sweep", LOOP_LINE, LOOP_LINE.replace(
        "policy.act(obs,", "policy.act(obs + np.random.default_rng(t).normal(0, 0.5, obs.shape).astype(obs.dtype),"))  # fmt: skip
    capsys.readouterr()
    noisy.sweep(sweep_args(output))
    assert "2 cells, 0 already done" in capsys.readouterr().err
    with_noise = files.read_csv(output / "episodes.csv")
    assert [r["return"] for r in with_noise] != [r["return"] for r in original]
    assert len(cell_files(output)) == 4  # the original's two cells and the copy's two
    sweep.sweep(sweep_args(output))  # the original answers from its own cells, unchanged
    assert "2 cells, 2 already done" in capsys.readouterr().err
    assert files.read_csv(output / "episodes.csv") == original


def test_a_per_episode_column_added_in_a_sweep_copy_reaches_episodes_csv(tmp_path, capsys):
    """The documented way (the sweep's docstring, "Changing the episodes"): one more entry of the dict that
    evaluate_cell returns. Its column reaches the cells and episodes.csv, and the original sweep, in the same
    output, still writes its own columns."""
    measuring = sweep_copy(tmp_path, "measuring_sweep", RETURN_LINE,
                           RETURN_LINE.replace("}", ', "final_position": obs[:, 0].astype(np.float64)}'))  # fmt: skip
    output = measuring.sweep(sweep_args(tmp_path / "out"))
    rows = files.read_csv(output / "episodes.csv")
    assert list(rows[0]) == [*cells.EPISODE_COLUMNS, "final_position"] and len(rows) == 12
    positions = [float(r["final_position"]) for r in rows]  # the cart's position when its episode ended
    assert all(np.isfinite(positions)) and len(set(positions)) > 1
    assert len(episodes.read_episodes([output])) == 12  # the one reader of episodes.csv takes it, column and all
    measuring.sweep(sweep_args(tmp_path / "out"))  # its cells, whole with their added column, are reused
    assert "2 already done" in capsys.readouterr().err
    sweep.sweep(sweep_args(tmp_path / "out"))
    assert list(files.read_csv(output / "episodes.csv")[0]) == cells.EPISODE_COLUMNS


def test_a_per_episode_column_with_a_name_of_the_sweeps_is_refused_in_one_line(tmp_path):
    clashing = sweep_copy(tmp_path, "clashing_sweep", RETURN_LINE, RETURN_LINE.replace("}", ', "seed": lengths}'))
    with pytest.raises(files.InputError, match="no checkpoint could be evaluated"):
        clashing.sweep(sweep_args(tmp_path / "out"))
    reasons = {r["reason"] for r in files.read_csv(tmp_path / "out" / "skipped.csv")}
    expected = (f"{FIXTURE}: evaluate_cell's column 'seed' is refused: per-episode columns it adds need a name of "
                "their own (letters, digits, underscores; none of the sweep's columns)")  # fmt: skip
    assert reasons == {expected}


@pytest.mark.slow
def test_an_edit_to_a_project_module_that_act_calls_re_evaluates_the_cells(tmp_path):
    """In a copy of the project: a rerun reuses every cell; after an edit to the module of guided_actions
    (which Agent.act calls, and the sweep imports nowhere itself), a rerun evaluates every cell again."""
    project = tmp_path / "project"
    shutil.copytree(ROOT / "pgg_utils", project / "pgg_utils", ignore=shutil.ignore_patterns("__pycache__"))
    for script in ("eval_gamma_sweep.py", "ppo_pgg_discrete.py", "ppo_pgg_continuous.py"):
        shutil.copy(ROOT / script, project / script)
    acted_with = Path(inspect.getsourcefile(ppo_pgg_discrete.guided_actions)).relative_to(ROOT)
    assert acted_with.parts[0] == "pgg_utils"

    def sweep_in_copy() -> str:
        proc = subprocess.run([sys.executable, str(project / "eval_gamma_sweep.py"), str(FIXTURE), "--gammas", "1",
                               "2", "--episodes", "2", "--output", str(tmp_path / "out")],
                              capture_output=True, text=True, timeout=300, cwd=tmp_path)  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        return proc.stderr

    assert "2 cells, 0 already done" in sweep_in_copy()
    assert "2 cells, 2 already done" in sweep_in_copy()
    with open(project / acted_with, "a") as f:
        f.write("\n# an edit\n")
    assert "2 cells, 0 already done" in sweep_in_copy()


# --- returns are the task's own ---------------------------------------------------------------------------

SCALED_MAKE_ENV = '''

def make_env(env_id: str, video_dir=None, render_mode=None):
    """A fork's reward scale, where a CleanRL user adds wrappers{recorder_note}."""

    def thunk():
        env = gym.make(env_id, render_mode=render_mode)
        {recorder}return gym.wrappers.TransformReward(env, lambda reward: 0.5 * reward)

    return thunk
'''


@pytest.mark.parametrize("recorded", [True, False])
def test_a_reward_scale_in_make_env_leaves_the_sweeps_returns_raw(tmp_path, recorded):
    """A fork's make_env that scales the reward: with RecordEpisodeStatistics directly on the task, the sweep
    reports the task's own returns (those of the original script); a make_env without one (a script from before
    it held one) is summed, as its training logged it: the scaled returns."""
    fork = tmp_path / "ppo_pgg_discrete.py"  # the fixture's script name: the fork evaluates it with --script
    recorder = "env = gym.wrappers.RecordEpisodeStatistics(env)\n        " if recorded else ""
    fork.write_text((ROOT / "ppo_pgg_discrete.py").read_text() + SCALED_MAKE_ENV.format(
        recorder=recorder, recorder_note=", outside the task's recorder" if recorded else ""))  # fmt: skip
    original = sweep.sweep(sweep_args(tmp_path / "original"))
    forked = sweep.sweep(sweep_args(tmp_path / "fork", script=(str(fork),)))
    raw = np.array([float(r["return"]) for r in files.read_csv(original / "episodes.csv")])
    swept = np.array([float(r["return"]) for r in files.read_csv(forked / "episodes.csv")])
    assert raw.min() > 0 and np.array_equal(swept, raw if recorded else 0.5 * raw)
    assert {r["evaluated_by"] for r in files.read_csv(forked / "evaluated_by.csv")} == {str(fork)}


def test_video_makes_its_env_with_the_scripts_make_env(monkeypatch):
    pytest.importorskip("pygame", reason="CartPole renders with pygame (the [video] extra)")
    made = []

    def make_env(env_id, video_dir=None, render_mode=None):
        made.append(render_mode)
        return lambda: gym.make(env_id, render_mode=render_mode)

    monkeypatch.setattr(ppo_pgg_discrete, "make_env", make_env)
    agent, ckpt = evaluation.load_any_checkpoint(FIXTURE)
    policy = evaluation.GuidedPolicy(agent, ckpt, module=ppo_pgg_discrete)
    frames, total, _ = video.record_episode(policy, ckpt, 1.0, 3, 10_000, 1, True)
    assert made == [None, "rgb_array", None] and len(frames) == total + 1 and frames[0].ndim == 3


def test_the_code_of_a_cell_is_read_from_import_statements(tmp_path):
    """A fork's helper module beside it (imported inside a function too) and the project modules it imports,
    transitively, are part of a cell's code; installed packages and the standard library are not."""
    from pgg_utils import cells

    (tmp_path / "ppo_fork.py").write_text("import json\nimport torch\nfrom pgg_utils import fast\n\n\n"
                                          "def make_env():\n    import fork_helpers\n")  # fmt: skip
    (tmp_path / "fork_helpers.py").write_text("from pgg_utils.arguments import acting_error\n")
    found = cells.imported_files([tmp_path / "ppo_fork.py"])
    package = ROOT / "pgg_utils"
    assert {tmp_path / "ppo_fork.py", tmp_path / "fork_helpers.py"} | {
        package / name for name in ("__init__.py", "fast.py", "arguments.py")
    } <= set(found)
    assert all(path.parent in (tmp_path, package) for path in found)  # no torch, no json


RECORDED_MAKE_ENV = """

def make_env(env_id: str, video_dir=None, render_mode=None):
    def thunk():
        return gym.wrappers.FlattenObservation(gym.wrappers.RecordEpisodeStatistics(gym.make(env_id, render_mode=render_mode)))

    return thunk
"""


def test_a_recorded_return_is_the_summed_one_to_the_last_bit(tmp_path):
    """A shipped Hopper agent swept through a make_env with RecordEpisodeStatistics on the task and through one
    without: the same float64 additions in the same order, so the same digits (committed episodes regenerate)."""
    fork = tmp_path / "ppo_pgg_continuous.py"
    fork.write_text((ROOT / "ppo_pgg_continuous.py").read_text() + RECORDED_MAKE_ENV)
    agent = min((ROOT / "results" / "continuous" / "agents").glob("Hopper-v4__ppo__s1/checkpoints/step_*.pt"))
    args = sweep.Args(paths=(str(agent),), gammas=(1.0,), episodes=2, output=str(tmp_path / "summed"))
    summed = files.read_csv(sweep.sweep(args) / "episodes.csv")
    recorded = files.read_csv(sweep.sweep(replace(args, output=str(tmp_path / "recorded"), script=(str(fork),))) /
                              "episodes.csv")  # fmt: skip
    assert [r["return"] for r in recorded] == [r["return"] for r in summed]
    assert evaluation.records_episodes(
        scripts.load_module(fork).make_env("Hopper-v4")()
    )  # the fork's path is the recorder's
    assert all(float(r["return"]) != int(float(r["return"])) for r in summed)  # fractional: float sums, not counts
