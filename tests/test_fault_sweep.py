"""Faults a sweep must survive without passing anything wrong on to episodes.csv and summary.csv:
damaged cell files, a full disk, another evaluation stack, drifting script defaults, diverged models,
and checkpoints of both formats (the committed fixtures, tests/fixtures/README.md)."""

import errno
import math
import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT, train

import eval_gamma_sweep as sweep
import ppo_pgg_continuous
import ppo_pgg_discrete
from pgg_utils import cells, checkpoints, episodes, evaluation, files, identity
from pgg_utils import sweep as engine

FIXTURES = Path(__file__).resolve().parent / "fixtures"
FORMAT_1 = FIXTURES / "cartpole_format1" / "checkpoints" / "step_000000512.pt"
FORMAT_2 = FIXTURES / "cartpole_format2" / "checkpoints" / "step_000000512.pt"
FIXTURE_LABEL = "ppo num_envs=2 num_steps=64 total_timesteps=512"  # CleanRL's defaults but for these three


def sweep_args(output: Path, *paths: Path, **overrides) -> sweep.Args:
    paths = tuple(str(p) for p in paths or (FORMAT_2,))
    return replace(sweep.Args(paths=paths, output=str(output), gammas=(1.0, 2.0), episodes=20), **overrides)


def outputs(output: Path) -> tuple[str, str]:
    return (output / "episodes.csv").read_text(), (output / "summary.csv").read_text()


def count_jobs(monkeypatch) -> list:
    evaluated, real_run_job = [], engine.run_job
    monkeypatch.setattr(engine, "run_job", lambda job: evaluated.append(job) or real_run_job(job))
    return evaluated


def test_the_sweep_shares_the_packages_classes():
    """Callers catch pgg_utils' InputError, and plot_results reports the sweep's statistic: one summary over seeds."""
    from paper_study import summary

    assert sweep.InputError is engine.InputError is files.InputError
    assert engine.summarise is summary.summarise_seeds is episodes.summarise


# --- damaged cells are evaluated again -----------------------------------------------------------------


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    """A whole sweep of the format-2 fixture: 20 episodes at γ 1 and 2."""
    return sweep.sweep(sweep_args(tmp_path_factory.mktemp("clean") / "out"))


def cut_row(text: str) -> str:
    return text[: text.rstrip("\n").rfind("\n") + 30]  # the last row ends 30 characters in


def changed_return(text: str) -> str:
    header, first, *rest = text.splitlines(keepends=True)
    values = first.split(",")
    values[header.split(",").index("return")] = "99999"
    return "".join([header, ",".join(values), *rest])


def duplicated_episode(text: str) -> str:
    header, first, _, *rest = text.splitlines(keepends=True)
    return "".join([header, first, first, *rest])  # 20 rows, each checksum whole, episode 0 twice


CORRUPTIONS = {
    "empty": lambda text, other: b"",
    "header only": lambda text, other: text.splitlines(keepends=True)[0].encode(),
    "10 of 20 rows": lambda text, other: "".join(text.splitlines(keepends=True)[:11]).encode(),
    "a return changed": lambda text, other: changed_return(text).encode(),
    "random bytes": lambda text, other: np.random.default_rng(0).bytes(3000),
    "a row cut mid-way": lambda text, other: cut_row(text).encode(),
    "an episode twice": lambda text, other: duplicated_episode(text).encode(),
    "another cell's rows": lambda text, other: other.encode(),
}


@pytest.mark.parametrize("corruption", CORRUPTIONS)
def test_a_damaged_cell_is_evaluated_again_and_nothing_of_it_reaches_the_outputs(clean, tmp_path, monkeypatch, capsys,
                                                                                   corruption):  # fmt: skip
    output = tmp_path / "out"
    shutil.copytree(clean, output)
    gamma_1, gamma_2 = sorted((output / "cells").glob("*.csv"), key=lambda p: "__g2__" in p.name)
    gamma_2.write_bytes(CORRUPTIONS[corruption](gamma_2.read_text(), gamma_1.read_text()))
    evaluated = count_jobs(monkeypatch)
    sweep.sweep(sweep_args(output))
    stderr = capsys.readouterr().err
    assert [(job.checkpoint, job.gamma) for job in evaluated] == [(FORMAT_2, 2.0)]
    assert f"re-evaluating {gamma_2}: " in stderr and "Traceback" not in stderr, stderr
    assert outputs(output) == outputs(clean)
    assert gamma_2.read_bytes() == (clean / "cells" / gamma_2.name).read_bytes()


def test_a_whole_cell_is_reused_without_a_word(clean, tmp_path, monkeypatch, capsys):
    shutil.copytree(clean, tmp_path / "out")
    evaluated = count_jobs(monkeypatch)
    sweep.sweep(sweep_args(tmp_path / "out"))
    assert evaluated == [] and "re-evaluating" not in capsys.readouterr().err
    assert outputs(tmp_path / "out") == outputs(clean)


# --- a full disk ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("failing", ["write", "rename"])
def test_a_full_disk_is_one_line_naming_the_file_and_leaves_no_temporary_file(tmp_path, monkeypatch, capsys, failing):
    full = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    real_open = open

    def open_on_a_full_disk(file, mode="r", *args, **kwargs):
        if "w" in mode:
            real_open(file, mode, *args, **kwargs).close()  # a full disk leaves the file empty
            raise full
        return real_open(file, mode, *args, **kwargs)

    def rename_on_a_full_disk(source, target):
        raise full

    if failing == "write":
        monkeypatch.setattr(files, "open", open_on_a_full_disk, raising=False)
    else:
        monkeypatch.setattr(files.os, "replace", rename_on_a_full_disk)
    output = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["eval_gamma_sweep.py", str(FORMAT_2), "--output", str(output), "--episodes", "2"])
    with pytest.raises(SystemExit) as exit_info:
        sweep.main()
    stderr = capsys.readouterr().err
    last = stderr.strip().splitlines()[-1]
    assert exit_info.value.code == 1 and "Traceback" not in stderr, stderr
    cell = rf"{re.escape(str(output / 'cells'))}/\S+\.csv"
    assert re.fullmatch(rf"error: cannot write {cell}: No space left on device", last), last
    assert not list(output.rglob("*.tmp")) and not list((output / "cells").iterdir())


# --- the evaluation stack ----------------------------------------------------------------------------------


def test_rows_record_the_stack_and_a_cell_of_another_mujoco_is_evaluated_again(tmp_path, monkeypatch):
    assert cells.EPISODE_COLUMNS[-5:] == ["mujoco", "gymnasium", "numpy", "torch", "action_space"]
    real_versions = checkpoints.package_versions
    monkeypatch.setattr(checkpoints, "package_versions", lambda: {**real_versions(), "mujoco": "2.3.3"})
    args = sweep_args(tmp_path / "out", episodes=4)
    sweep.sweep(args)
    elsewhere = files.read_csv(tmp_path / "out" / "episodes.csv")
    assert {row["mujoco"] for row in elsewhere} == {"2.3.3"}
    monkeypatch.setattr(checkpoints, "package_versions", real_versions)
    evaluated = count_jobs(monkeypatch)
    sweep.sweep(args)
    assert len(evaluated) == 2  # not the cells of the other MuJoCo
    here = files.read_csv(tmp_path / "out" / "episodes.csv")
    versions = real_versions()
    for row in here:
        assert [row[p] for p in cells.STACK_COLUMNS] == [versions[p] or "none" for p in cells.STACK_COLUMNS]
        assert row["action_space"] == "discrete"
    assert [(r["return"], r["length"]) for r in here] == [(r["return"], r["length"]) for r in elsewhere]
    assert len(list((tmp_path / "out" / "cells").glob("*.csv"))) == 4  # both kept, each under its own stack


# --- configurations ---------------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_configuration_is_named_against_the_frozen_reference_not_the_scripts_defaults(tmp_path):
    """Seed 1 swept by this process and seed 2 by a later one, after the script's default ent_coef
    moved to 0.02: both were trained at 0.01, CleanRL's, and stay one configuration of two seeds."""
    ckpt = torch.load(FORMAT_2, weights_only=True)
    assert ckpt["args"]["ent_coef"] == 0.01 and identity.config_label(ckpt) == FIXTURE_LABEL
    reference = {**identity.FROZEN_DEFAULTS["discrete"], "seed": 3, "output_dir": "x", "env_id": "CartPole-v1"}
    todays_labels = {
        "pgg_g1.1": {"guidance": 1.1},
        "ppo total_timesteps=50000": {"total_timesteps": 50_000},
        "pgg_drop0.1 learning_rate=0.002": {"cond_dropout": 0.1, "learning_rate": 0.002},
    }
    for label, changes in todays_labels.items():
        assert identity.config_label({**ckpt, "args": {**reference, **changes}}) == label
    seed_2 = tmp_path / "seed_2" / "checkpoints" / FORMAT_2.name
    seed_2.parent.mkdir(parents=True)
    torch.save({**ckpt, "args": {**ckpt["args"], "seed": 2}}, seed_2)
    sweep.sweep(sweep_args(tmp_path / "before", gammas=(1.0,), episodes=4))
    drifted = f"""
import dataclasses, sys
sys.path.insert(0, {str(ROOT)!r})
import ppo_pgg_discrete
ppo_pgg_discrete.Args = dataclasses.make_dataclass("Args", [("ent_coef", float, 0.02)], bases=(ppo_pgg_discrete.Args,))
import eval_gamma_sweep as sweep
sweep.sweep(sweep.Args(paths=({str(seed_2)!r},), output={str(tmp_path / "after")!r}, gammas=(1.0,), episodes=4))
"""
    proc = subprocess.run([sys.executable, "-c", drifted], check=False, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = [*files.read_csv(tmp_path / "before" / "episodes.csv"), *files.read_csv(tmp_path / "after" / "episodes.csv")]
    (series,) = engine.summary_rows(rows)
    assert series["config"] == FIXTURE_LABEL and series["n_seeds"] == 2


# --- diverged models -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def hopper(tmp_path_factory) -> Path:
    """A Hopper checkpoint of one 64-step iteration."""
    args = ppo_pgg_continuous.Args(
        env_id="Hopper-v4", total_timesteps=64, num_steps=64, num_minibatches=2, update_epochs=1,
        checkpoint_interval=64, output_dir=str(tmp_path_factory.mktemp("hopper")),
    )  # fmt: skip
    return checkpoints.checkpoint_path(train(ppo_pgg_continuous, args), 64)


def with_nan(source: Path, target: Path, tensor: str) -> Path:
    ckpt = torch.load(source, weights_only=True)
    ckpt["model"][tensor] = torch.full_like(ckpt["model"][tensor], math.nan)
    target.parent.mkdir(parents=True)
    torch.save(ckpt, target)
    return target


def test_a_checkpoint_with_non_finite_weights_or_statistics_is_skipped_never_evaluated(hopper, tmp_path, monkeypatch):
    cartpole = with_nan(FORMAT_2, tmp_path / "cartpole_nan" / "checkpoints" / FORMAT_2.name, "null_obs")
    hopper = with_nan(hopper, tmp_path / "hopper_nan" / "checkpoints" / hopper.name, "actor_mean.0.weight")
    (tmp_path / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "cwd")  # where MuJoCo would write MUJOCO_LOG.TXT about NaN controls
    evaluated = count_jobs(monkeypatch)
    with pytest.raises(files.InputError, match="no checkpoint could be evaluated"):
        sweep.sweep(sweep_args(tmp_path / "out", cartpole, hopper, gammas=(1.0, 1.5), episodes=2))
    assert evaluated == [] and files.read_csv(tmp_path / "out" / "episodes.csv") == []
    reasons = [row["reason"] for row in files.read_csv(tmp_path / "out" / "skipped.csv")]
    assert len(reasons) == 2 and str(cartpole) in reasons[0] and str(hopper) in reasons[1]
    assert "non-finite" in reasons[0] and "null_obs" in reasons[0] and "actor_mean.0.weight" in reasons[1]
    assert not (tmp_path / "cwd" / "MUJOCO_LOG.TXT").exists()


# --- checkpoints of both formats -----------------------------------------------------------------------


@pytest.mark.parametrize("path,version", [(FORMAT_1, 1), (FORMAT_2, 2)])
def test_fixture_checkpoints_of_both_formats_load_and_sweep_to_finite_returns(tmp_path, path, version):
    agent, ckpt = evaluation.load_any_checkpoint(path)
    assert ckpt["format_version"] == version and ("resume" in ckpt) == ("versions" in ckpt) == (version == 2)
    assert torch.equal(agent.null_obs.detach(), ckpt["model"]["null_obs"])
    out = sweep.sweep(sweep_args(tmp_path / "out", path, episodes=2))
    rows = files.read_csv(out / "episodes.csv")
    assert [(r["eval_guidance"], r["episode"]) for r in rows] == [(g, k) for g in ("1.0", "2.0") for k in ("0", "1")]
    assert all(math.isfinite(float(r["return"])) and int(r["length"]) > 0 for r in rows)
    # Format 1 records no versions: a configuration of its own. The training code's revision is never part of one.
    label = FIXTURE_LABEL + (" versions=unknown" if version == 1 else "")
    assert {r["config"] for r in rows} == {label}
    without_code = {key: value for key, value in ckpt.items() if key != "code"}
    code = {"commit": "0" * 40, "modified": True, "sha1": "1" * 40}
    assert identity.config_label({**ckpt, "code": code}) == identity.config_label(without_code) == label


# --- a task that changed or went away after training -----------------------------------------------------

TASK = """
import math

import gymnasium as gym
import numpy as np


class Walk(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), np.float32)
    action_space = gym.spaces.Discrete(N_ACTIONS)

    def __init__(self, render_mode=None):
        self.render_mode = render_mode

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(OBS_DIM, np.float32), {}

    def step(self, action):
        self.t += 1
        if RAISE_AT == self.t:
            raise RuntimeError("the simulator diverged")
        reward = math.nan if NAN_AT == self.t else 1.0
        obs = self.np_random.normal(size=OBS_DIM).astype(np.float32)
        if NAN_OBS_AT == self.t:
            obs[0] = math.nan
        return obs, reward, False, self.t >= 30, {}


gym.register("FaultWalk-v0", entry_point=Walk, **REGISTER)
"""
# The task as it is trained; a test changes some of these for the sweep.
TASK_SETTINGS = {"NAN_AT": None, "RAISE_AT": None, "NAN_OBS_AT": None, "OBS_DIM": 2, "N_ACTIONS": 2,
                 "REGISTER": "dict(max_episode_steps=30)"}  # fmt: skip


def task_module(path: Path, **settings) -> None:
    path.write_text("".join(f"{name} = {value}\n" for name, value in {**TASK_SETTINGS, **settings}.items()) + TASK)


def trained_on_custom_task(tmp_path, monkeypatch, nan_at=None, register="max_episode_steps=30", trained=None,
                           **swept) -> Path:  # fmt: skip
    """A tiny discrete run on a task of a module of its own (with the `trained` settings of TASK_SETTINGS),
    then that module rewritten for the sweep: NaN rewards from step `nan_at`, registered with `register`
    (its time limit), and the `swept` settings."""
    module = tmp_path / "tasks" / "fault_walk_task.py"
    module.parent.mkdir(parents=True, exist_ok=True)
    task_module(module, **(trained or {}))
    monkeypatch.syspath_prepend(str(module.parent))
    forget_task()
    args = tiny_discrete_args(tmp_path, "fault_walk_task:FaultWalk-v0")
    run_dir = train(ppo_pgg_discrete, args)
    task_module(module, NAN_AT=nan_at, REGISTER=f"dict({register})", **swept)
    forget_task()
    return run_dir


def forget_task() -> None:
    """Drops the task's module and registration from this process, as a new process would start."""
    sys.modules.pop("fault_walk_task", None)
    gym.registry.pop("FaultWalk-v0", None)


def tiny_discrete_args(tmp_path, env_id: str):
    return ppo_pgg_discrete.Args(env_id=env_id, output_dir=str(tmp_path / "runs"), total_timesteps=512,
                                 checkpoint_interval=512, num_steps=64)  # fmt: skip


def test_nan_returns_are_never_written_as_results(tmp_path, monkeypatch):
    run_dir = trained_on_custom_task(tmp_path, monkeypatch, nan_at=3)
    with pytest.raises(files.InputError, match="no checkpoint could be evaluated"):
        sweep.sweep(sweep_args(tmp_path / "out", run_dir, episodes=4))
    (skipped,) = files.read_csv(tmp_path / "out" / "skipped.csv")
    assert "returned nan (a non-finite reward); none of its cells is tabled" in skipped["reason"]
    assert "nan" not in (tmp_path / "out" / "episodes.csv").read_text()


def test_a_task_without_a_time_limit_is_refused_in_one_line_before_any_episode(tmp_path, monkeypatch):
    run_dir = trained_on_custom_task(tmp_path, monkeypatch, register="")
    evaluated = count_jobs(monkeypatch)
    with pytest.raises(files.InputError, match="no checkpoint could be evaluated"):
        sweep.sweep(sweep_args(tmp_path / "out", run_dir, episodes=4))
    (skipped,) = files.read_csv(tmp_path / "out" / "skipped.csv")
    assert "has no time limit (max_episode_steps)" in skipped["reason"] and not evaluated


@pytest.mark.slow
def test_a_task_whose_module_is_gone_is_skipped_in_one_line(tmp_path, monkeypatch):
    run_dir = trained_on_custom_task(tmp_path, monkeypatch)
    (tmp_path / "tasks" / "fault_walk_task.py").unlink()
    proc = subprocess.run([sys.executable, str(ROOT / "eval_gamma_sweep.py"), str(run_dir), "--output",
                           str(tmp_path / "out"), "--episodes", "2"], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "cannot make environment 'fault_walk_task:FaultWalk-v0' (ModuleNotFoundError" in proc.stderr


def swept_beside_a_good_checkpoint(run_dir: Path, tmp_path, capsys) -> tuple[list[dict], str]:
    """Sweeps `run_dir` with the format-2 fixture beside it; (the rows of skipped.csv, stderr). The fixture's
    episodes must all be there: the sweep went on."""
    output = sweep.sweep(sweep_args(tmp_path / "out", run_dir, FORMAT_2, episodes=4))
    stderr = capsys.readouterr().err
    rows = files.read_csv(output / "episodes.csv")
    assert {r["run"] for r in rows} == {"cartpole_format2"} and len(rows) == 8, stderr
    assert "Traceback" not in stderr, stderr
    return files.read_csv(output / "skipped.csv"), stderr


def the_one_skip(skipped: list[dict], stderr: str, run_dir: Path) -> str:
    """The one reason of skipped.csv, checked to name a checkpoint of `run_dir` and to be on stderr, in one line."""
    (row,) = skipped
    reason = row["reason"]
    assert reason.startswith(str(run_dir)) and "\n" not in reason
    assert [line for line in stderr.splitlines() if line.startswith("skipped ")] == [f"skipped {reason}"]
    return reason


@pytest.mark.parametrize(
    "swept,message",
    [
        ({"RAISE_AT": 5}, "episode 0 at γ = 1: the task raised RuntimeError: the simulator diverged at step 5"),
        ({"NAN_OBS_AT": 7}, "episode 0 at γ = 1: the task returned a non-finite observation at step 7"),
    ],
)
def test_a_task_that_fails_mid_episode_skips_its_checkpoint_and_the_sweep_goes_on(tmp_path, monkeypatch, capsys,
                                                                                  swept, message):  # fmt: skip
    run_dir = trained_on_custom_task(tmp_path, monkeypatch, **swept)
    capsys.readouterr()
    reason = the_one_skip(*swept_beside_a_good_checkpoint(run_dir, tmp_path, capsys), run_dir)
    assert message in reason and reason.endswith("none of its cells is tabled"), reason


@pytest.mark.parametrize(
    "trained,swept,message",
    [
        ({"OBS_DIM": 3}, {"OBS_DIM": 1}, "has changed since training: observation shape (3,) in training, (1,) now"),
        ({"N_ACTIONS": 1}, {"N_ACTIONS": 4}, "has changed since training: action n 1 in training, 4 now"),
    ],
)
def test_a_task_whose_spaces_changed_since_training_is_skipped_in_one_line(tmp_path, monkeypatch, capsys, trained,
                                                                            swept, message):  # fmt: skip
    run_dir = trained_on_custom_task(tmp_path, monkeypatch, trained=trained, **swept)
    capsys.readouterr()
    evaluated = count_jobs(monkeypatch)
    reason = the_one_skip(*swept_beside_a_good_checkpoint(run_dir, tmp_path, capsys), run_dir)
    assert message in reason, reason
    assert {job.checkpoint.parent.parent for job in evaluated} == {FORMAT_2.parent.parent}  # never played


def test_video_of_a_checkpoint_whose_task_changed_is_one_line(tmp_path, monkeypatch):
    run_dir = trained_on_custom_task(tmp_path, monkeypatch, trained={"OBS_DIM": 3}, OBS_DIM=1)
    checkpoint = checkpoints.checkpoints_of(run_dir)[-1]
    args = sweep.Args(paths=(str(checkpoint),), gammas=(1.0,), video=str(tmp_path / "videos"))
    with pytest.raises(files.InputError, match=r"has changed since training: observation shape \(3,\) in training"):
        sweep.record_videos(args)
    assert not (tmp_path / "videos").exists()


BOX_TASK = """
import gymnasium as gym
import numpy as np


class Reach(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, SHAPE, np.float32)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(3, np.float32), {}

    def step(self, action):
        self.t += 1
        return self.np_random.normal(size=3).astype(np.float32), -float(np.square(action).sum()), False, self.t >= 20, {}


gym.register("BoxReach-v0", entry_point=Reach, max_episode_steps=20)
"""


def test_a_box_action_of_two_dimensions_is_refused_in_one_line_not_broadcast(tmp_path, monkeypatch, capsys):
    """A task whose Box action became (2, 2) after training on a flat Box(4): the sweep acts with flat vectors,
    so it refuses the checkpoint in one line, never a broadcast error (training refuses such a space itself)."""
    module = tmp_path / "tasks" / "box_reach_task.py"
    module.parent.mkdir()
    module.write_text("SHAPE = (4,)\n" + BOX_TASK)
    monkeypatch.syspath_prepend(str(module.parent))
    run_dir = train(ppo_pgg_continuous, ppo_pgg_continuous.Args(
        env_id="box_reach_task:BoxReach-v0", output_dir=str(tmp_path / "runs"), total_timesteps=256, num_steps=128,
        num_minibatches=2, update_epochs=1, checkpoint_interval=256,
    ))  # fmt: skip
    module.write_text("SHAPE = (2, 2)\n" + BOX_TASK)
    sys.modules.pop("box_reach_task", None)
    gym.registry.pop("box_reach_task:BoxReach-v0", None)
    gym.registry.pop("BoxReach-v0", None)
    reason = the_one_skip(*swept_beside_a_good_checkpoint(run_dir, tmp_path, capsys), run_dir)
    assert "actions are a Box of shape (2, 2)" in reason and "broadcast" not in reason, reason
