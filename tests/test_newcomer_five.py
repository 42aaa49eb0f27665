"""What a newcomer broke, round five, and what a user of the ecosystem's tools hit (issue 59): unchecked noise, a
seed lost from a whole configuration, a manifest that could delete a user's file, aggregates left out without a
word on a user's own tasks; the loud cases, each one line naming its real cause; and the field's habits
(Stable-Baselines3's `predict`, a per-call seed)."""

import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import matplotlib
import numpy as np
import pytest
import torch
from conftest import ROOT, SCRIPTS, small_args, train
from test_plots import SEED_MEANS, episode_rows, one_error_line, run_cli, summary_of, write_episodes

import eval_gamma_sweep as sweep
import plot_results as plots
import ppo_pgg_discrete
from paper_study import agents, figures
from paper_study import aggregate as aggregation
from pgg_utils import cells, checkpoints, runs
from pgg_utils.arguments import answer_cleanrl_habits
from pgg_utils.checks import env_error
from pgg_utils.files import MANIFEST, read_csv, read_manifest, sha256_of

FORMAT_2 = Path(__file__).resolve().parent / "fixtures" / "cartpole_format2" / "checkpoints" / "step_000000512.pt"


# --- silent: act's noise --------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_refuses_noise_that_is_not_finite_in_one_line_naming_it(kind):
    """NaN noise returned NaN actions, an infinite one the bound, and on a discrete agent `[nan, nan, nan]` the
    argmax's first action whatever the observation: noise is checked as the observation is."""
    agent = SCRIPTS[kind].Agent(4, 3)
    for bad in (np.full(3, np.nan), np.full(3, np.inf), np.array([[0.0, -np.inf, 0.0]])):
        with pytest.raises(ValueError, match=r"^noise holds a NaN or an infinity$"):
            agent.act(np.zeros(4), 1.5, noise=bad)


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_act_names_noise_of_the_wrong_shape_and_the_shape_it_needs(kind):
    """numpy's "operands could not be broadcast together with shapes (3,) (5,)" named no argument, and a noise that
    broadcast (one number for every action, a batch's noise for one observation) acted silently."""
    agent = SCRIPTS[kind].Agent(4, 3)
    one = "the agent's noise is (3,) or (1, 3)"
    for noise, shape, wanted in ((np.zeros(5), "(5,)", one), (np.zeros(1), "(1,)", one), (np.zeros(()), "()", one),
                                 (np.zeros((2, 3)), "(2, 3)", one)):  # fmt: skip
        with pytest.raises(ValueError) as refused:
            agent.act(np.zeros(4), 1.0, noise=noise)
        assert str(refused.value) == f"noise has shape {shape}; for one observation {wanted}"
    with pytest.raises(ValueError) as refused:
        agent.act(np.zeros((5, 4)), 1.0, noise=np.zeros(3))
    assert str(refused.value) == "noise has shape (3,); for 5 observations the agent's noise is (5, 3)"
    state = torch.get_rng_state()
    assert (
        agent.act(np.zeros(4), 1.0, noise=np.zeros(3)).shape
        == agent.act(np.zeros(4), 1.0, noise=np.zeros((1, 3))).shape
    )
    assert torch.equal(torch.get_rng_state(), state)  # checking the shape draws nothing from torch's generator


# --- silent: a configuration short of seeds in every cell -----------------------------------------


@pytest.mark.slow
def test_a_configuration_short_of_a_seed_in_every_cell_is_marked_against_the_others(tmp_path, capsys):
    """With no written.csv and one variant's seed 2 gone from every cell, the tables showed that variant's 2-seed
    cells bare under "mean ± 95% CI over seeds" beside the others' 3, and no note: only a cell short within its own
    configuration was marked."""
    rows = [r for r in episode_rows(SEED_MEANS) if r["run"] != "CartPole-v1__pgg_g1.1__s2"]
    write_episodes(tmp_path / "sweep" / "episodes.csv", rows)
    plots.generate(plots.Args(sweeps=(str(tmp_path / "sweep"),), output=str(tmp_path / "out")))
    err = capsys.readouterr().err
    assert ("note: 1 configuration(s) hold fewer seeds in every cell than the other configurations of their task, "
            "and say so in the tables: CartPole-v1 pgg_g1.1 (2 of 3 seeds)") in err  # fmt: skip
    assert "cell(s) hold fewer seeds than the other cells of their configuration" not in err
    table = (tmp_path / "out" / "table_discrete.md").read_text()
    assert table.count("(2 of 3 seeds)") == 4  # CartPole's four PGG cells, at two steps and two γ
    assert "467.0 ± 12.7 (2 of 3 seeds)" in table
    assert "(2 of 3 seeds)" in (tmp_path / "out" / "table_discrete.tex").read_text()


# --- silent: outputs.txt names only files plot_results.py wrote ------------------------------------


@pytest.mark.slow
def test_a_rerun_never_deletes_a_file_named_in_outputs_txt_by_hand_or_edited_since(tmp_path, capsys):
    """A name added to outputs.txt by hand made the next plot_results.py run delete that file of the user's: the
    manifest records each output's sha256, and a rerun removes only the files that are still the bytes it wrote."""
    both = {("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272], ("Hopper-v4", "ppo", 200000, 1.0): [1000, 1100, 1200]}
    write_episodes(tmp_path / "both.csv", episode_rows(both))
    write_episodes(tmp_path / "cartpole.csv", episode_rows({k: v for k, v in both.items() if k[0] == "CartPole-v1"}))
    out = tmp_path / "out"

    def run(sweep: str) -> list:
        return plots.generate(plots.Args(sweeps=(str(tmp_path / sweep),), output=str(out)))

    run("both.csv")
    (out / "my_notes.md").write_text("the user's")
    (out / "table_continuous.md").write_text("the user's edit of a table")
    with open(out / MANIFEST, "a") as manifest:
        manifest.write("my_notes.md\n" + "0" * 64 + "  fig_continuous_ppo.png\n")  # by hand, a digest forged too
    capsys.readouterr()
    run("cartpole.csv")
    err = capsys.readouterr().err
    assert (out / "my_notes.md").read_text() == "the user's"
    assert (out / "table_continuous.md").read_text() == "the user's edit of a table"
    assert (out / "fig_continuous_ppo.png").exists() and not (out / "fig_continuous_ppo.pdf").exists()
    for name in ("fig_continuous_ppo.png", "my_notes.md", "table_continuous.md"):
        assert f"note: kept {out / name}: {out / MANIFEST} lists it, but not as the file a previous run wrote" in err
    assert f"note: removed {out / 'fig_continuous_ppo.pdf'}" in err
    assert not {"my_notes.md", "table_continuous.md", "fig_continuous_ppo.png"} & set(read_manifest(out))
    assert read_manifest(out)["table_discrete.md"] == sha256_of(out / "table_discrete.md")


# --- silent: the aggregates on a user's own tasks ------------------------------------------------


@pytest.mark.slow
def test_aggregates_on_a_task_the_paper_did_not_run_normalise_by_the_sweeps_own_ppo(tmp_path, capsys):
    """LunarLander or Swimmer got no aggregate IQM and no performance profile, without a word: where the paper has
    no row, the sweep's own PPO at γ = 1 is the reference (0 at its first step, 1 at its last), and the table and
    figures say which reference each task's scores use; a task with neither is named in one printed line."""
    means = {("MyTask-v0", "ppo", 1000, 1.0): [9, 10, 11], ("MyTask-v0", "ppo", 2000, 1.0): [19, 20, 21],
             ("MyTask-v0", "pgg_g1.1", 2000, 1.0): [24, 25, 26], ("MyTask-v0", "pgg_g1.1", 2000, 2.0): [29, 30, 31],
             ("CartPole-v1", "ppo", 100000, 1.0): [270, 271, 272], ("CartPole-v1", "ppo", 200000, 1.0): [300, 301, 302],
             ("Other-v0", "pgg_g1.1", 1000, 1.0): [1, 2, 3]}  # fmt: skip
    write_episodes(tmp_path / "episodes.csv", episode_rows(means, action_space="discrete"))
    plots.generate(plots.Args(sweeps=(str(tmp_path / "episodes.csv"),), output=str(tmp_path / "out")))
    err = capsys.readouterr().err
    assert ("note: the aggregate IQM and performance profile leave out the tasks with no reference to normalise by "
            "(Other-v0: the paper has no row for it and the sweep holds no PPO at eval γ = 1)") in err  # fmt: skip
    aggregate = {
        (r["variant"], r["step"], r["eval_guidance"]): r for r in read_csv(tmp_path / "out" / "aggregate_iqm.csv")
    }
    assert float(aggregate[("pgg_g1.1", "2000", "2.0")]["iqm"]) == 2.0  # (30 - 10) / (20 - 10), MyTask's alone
    assert aggregate[("pgg_g1.1", "2000", "2.0")]["n_envs"] == "1"
    said = ("0 = PPO at its first step, 1 = at its last: the paper's PPO for CartPole-v1; this sweep's PPO at γ = 1 "
            "for MyTask-v0")  # fmt: skip
    assert f"Scores normalised per task: {said}." in (tmp_path / "out" / "aggregate_iqm.md").read_text()
    summary = summary_of(tmp_path / "episodes.csv")
    assert (
        said in figures.aggregate_intervals(aggregation.aggregate_iqm(summary), "discrete", said).axes[0].get_xlabel()
    )
    assert (tmp_path / "out" / "performance_profile_discrete.png").exists()


def test_the_performance_profile_spans_the_scores_range(tmp_path):
    """Its τ axis ran from below 0 to past 1 whatever the scores (−4 to 8 on the continuous tables, with the
    informative region squeezed): it spans the scores, as rliable's own plots do."""
    write_episodes(tmp_path / "episodes.csv", episode_rows(SEED_MEANS))
    summary = summary_of(tmp_path / "episodes.csv")
    profiles, step, envs = aggregation.performance_profiles(summary)
    scores = np.concatenate(
        [np.concatenate(s) for (_, at, _), s in aggregation.normalised_scores(summary).items() if at == step]
    )
    fig = figures.performance_profiles(profiles, step, envs, "discrete")
    for ax in (ax for ax in fig.axes if ax.get_visible()):
        assert ax.get_xlim() == pytest.approx((scores.min(), scores.max()))
    matplotlib.pyplot.close(fig)


# --- loud --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_response_step_the_sweep_lacks_is_one_line_and_a_task_without_it_says_so_in_its_panel(tmp_path):
    """`--response-step 12345` raised an IndexError traceback in figures.seeds_label; a step that one task of the
    sweep holds and another does not crashed the same way."""
    write_episodes(tmp_path / "sweep" / "episodes.csv", episode_rows(SEED_MEANS))
    one_error_line(run_cli(tmp_path / "sweep", "--output", tmp_path / "o", "--response-step", "12345"),
                   "--response-step 12345: the sweeps hold no checkpoint at that step (their steps: 100000, 200000)")  # fmt: skip
    summary = [r for r in summary_of(tmp_path / "sweep") if not (r["env_id"] == "Acrobot-v1" and r["step"] == 200000)]
    fig = figures.gamma_response(summary, ["Acrobot-v1", "CartPole-v1"], 200000)
    assert [t.get_text() for t in fig.axes[0].texts] == ["not swept at 200k steps"] and fig.axes[1].get_lines()
    matplotlib.pyplot.close(fig)


def test_two_sweeps_of_the_same_checkpoints_with_other_eval_seeds_are_other_episodes(tmp_path):
    """`plot_results.py s1 s2` on sweeps made with --eval-seed 10000 and 20000 was refused with "episode 0 of run …
    appears in both …: pass each sweep once", though each was passed once and their episodes differ: an episode is
    its reset seed, so the two pool as one sweep of twice the episodes would; a reset seed in both is refused."""
    cell = {("CartPole-v1", "ppo", 100000, 1.0): [100.0, 200.0]}
    write_episodes(tmp_path / "s1" / "episodes.csv", episode_rows(cell))
    fresh = [r | {"episode_seed": r["episode_seed"] + 10_000, "return": r["return"] + 10} for r in episode_rows(cell)]
    write_episodes(tmp_path / "s2" / "episodes.csv", fresh)
    (row,) = summary_of(tmp_path / "s1", tmp_path / "s2")
    assert (row["n_episodes"], row["seed_means"]) == (8, "105.0000;205.0000")
    overlapping = [r | {"episode_seed": r["episode_seed"] + 1} for r in episode_rows(cell)]  # --eval-seed 10001
    write_episodes(tmp_path / "s3" / "episodes.csv", overlapping)
    with pytest.raises(plots.InputError) as refused:
        plots.read_episodes([tmp_path / "s1", tmp_path / "s3"])
    assert str(refused.value).startswith("episode 0 (reset seed 10001) of run CartPole-v1__ppo__s1 (100000 1.0 sample ")
    assert str(refused.value).endswith("s3/episodes.csv: one episode counted twice; pass each sweep once")


def test_a_folder_of_symlinks_to_run_directories_sweeps_as_the_runs_do(tmp_path):
    """The sweep said "no checkpoints (checkpoints/step_*.pt) under links/", though each symlink alone worked:
    Path.rglob follows no link to a folder. A link cycle ends the search instead of looping."""
    links = tmp_path / "links"
    links.mkdir()
    (links / "cartpole").symlink_to(FORMAT_2.parent.parent, target_is_directory=True)
    (links / "cartpole_again").symlink_to(links, target_is_directory=True)  # a cycle
    assert checkpoints.find_checkpoints([links]) == [links / "cartpole" / "checkpoints" / FORMAT_2.name]
    args = {"gammas": (1.0,), "episodes": 2}
    together = sweep.sweep(sweep.Args(paths=(str(links),), output=str(tmp_path / "together"), **args))
    alone = sweep.sweep(sweep.Args(paths=(str(links / "cartpole"),), output=str(tmp_path / "alone"), **args))
    assert (together / "episodes.csv").read_text() == (alone / "episodes.csv").read_text()
    (tmp_path / "elsewhere" / "run").mkdir(parents=True)
    (tmp_path / "elsewhere" / "run" / "args.json").write_text("{}")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "run").symlink_to(tmp_path / "elsewhere" / "run", target_is_directory=True)
    assert plots.run_args_files([tmp_path / "runs"]) == [tmp_path / "runs" / "run" / "args.json"]


@pytest.mark.slow
def test_resume_on_a_folder_holding_another_runs_checkpoint_names_the_checkpoint(tmp_path):
    """--resume where another run's checkpoint was copied in is refused (right), but the line blamed args.json
    ("args.json disagrees with the run's checkpoints: seed 1 (checkpoints: 2): restore it"), which is this run's."""
    args = small_args("discrete", tmp_path)
    mine = train(ppo_pgg_discrete, args)
    for later in (1024, 1536):  # as if stopped after its first checkpoint
        checkpoints.checkpoint_path(mine, later).unlink()
    theirs = train(ppo_pgg_discrete, replace(args, seed=2))
    foreign = checkpoints.checkpoint_path(mine, 1024)
    shutil.copy(checkpoints.checkpoint_path(theirs, 1024), foreign)
    with pytest.raises(runs.RunDirError) as refused:
        runs.Run.prepare(replace(args, resume=True), "discrete", Path(ppo_pgg_discrete.__file__))
    assert str(refused.value) == (
        f"{foreign} is not this run's checkpoint: it was written by run {theirs.name} (seed 2 -> 1: as recorded -> "
        f"as {mine / 'args.json'} and this command have it); move it out of {foreign.parent}, or pass --overwrite "
        "to start over"
    )


class FailingCartPole(gym.Wrapper):
    """CartPole whose step raises from its 150th call on: a custom task's bug, met after the first checkpoint."""

    def __init__(self, render_mode=None):
        super().__init__(gym.make("CartPole-v1", render_mode=render_mode))
        self.steps = 0

    def step(self, action):
        self.steps += 1
        if self.steps >= 150:
            raise RuntimeError("the pole's sensor failed\nsecond line")
        return self.env.step(action)


def test_a_task_that_raises_in_step_during_training_is_one_line_naming_the_checkpoints_kept(tmp_path, capsys):
    """A custom task raising inside step() gave a full traceback and no line saying which checkpoints are kept (the
    sweep said the same task's fault in one line); an error of the script's own still shows its traceback."""
    gym.register("FailingCartPole-v0", entry_point=FailingCartPole, max_episode_steps=500)
    try:
        args = small_args("discrete", tmp_path, env_id="FailingCartPole-v0", guidance=1.0, cond_dropout=0.0)
        with pytest.raises(SystemExit) as stopped:
            runs.launch(args, "discrete", ppo_pgg_discrete.__file__, ppo_pgg_discrete.train)
    finally:
        gym.registry.pop("FailingCartPole-v0")
    err = capsys.readouterr().err
    (run_dir,) = tmp_path.iterdir()
    assert stopped.value.code == 1 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == (
        f"error: the task raised RuntimeError: the pole's sensor failed, in its step() while {run_dir} trained; "
        "checkpoints up to step_000000512.pt are kept: fix the task and continue with --resume"
    )

    def broken(args, run):
        raise KeyError("the script's own bug")

    with pytest.raises(KeyError):
        runs.launch(replace(args, env_id="CartPole-v1"), "discrete", ppo_pgg_discrete.__file__, broken)


@pytest.mark.parametrize(
    "flags,answer",
    [
        (["--upload-model"], "upload nothing to the Hugging Face Hub"),
        (["--hf-entity", "me"], "upload nothing to the Hugging Face Hub"),
        (
            ["--num_iterations=10"],
            "the number of iterations is derived: ⌈--total-timesteps / (--num-envs × --num-steps)⌉",
        ),
    ],
)
def test_cleanrls_upload_and_iteration_flags_are_answered_in_one_line(flags, answer, capsys):
    """CleanRL's continuous script's --upload-model and --hf-entity, and its derived --num-iterations, met tyro's
    bare "Unrecognized options", where --gamma, --cuda and --batch-size got a one-line answer."""
    with pytest.raises(SystemExit) as refused:
        answer_cleanrl_habits(["--env-id", "Hopper-v4", *flags])
    (line,) = capsys.readouterr().err.splitlines()
    assert refused.value.code == 2 and line.startswith(f"error: {flags[0].split('=')[0]}: ") and answer in line
    assert answer_cleanrl_habits(["--no-upload-model"]) == []  # CleanRL's default: its meaning holds, with a note
    assert "note: --no-upload-model: " in capsys.readouterr().err


def test_an_id_a_module_registers_is_answered_with_the_module_prefix_and_dm_controls_numpy_limit():
    """CleanRL's dm_control test id and MiniGrid's ids met gymnasium's "Namespace dm_control not found" and
    "Environment `MiniGrid-Empty-5x5` doesn't exist", with no hint of the `shimmy:` / `minigrid:` prefix, nor of
    dm-control's numpy-2 limit that docs/usage.md states."""
    dm_control = env_error("dm_control/cartpole-balance-v0", "continuous")
    assert "--env-id shimmy:dm_control/cartpole-balance-v0 (pip install 'shimmy[dm-control]')" in dm_control
    assert "dm-control 1.0.14, the release for MuJoCo 2.3.7, fails on numpy 2" in dm_control
    assert "fails on numpy 2" in env_error("shimmy:dm_control/cartpole-balance-v0", "continuous")
    assert "--env-id minigrid:MiniGrid-Empty-5x5-v0 (pip install minigrid)" in env_error(
        "MiniGrid-Empty-5x5-v0", "discrete"
    )
    assert "--env-id module:Id" in env_error("mymodule/MyTask-v0", "discrete")
    assert "fails on numpy 2" in (ROOT / "docs" / "usage.md").read_text()  # where the hint sends the reader


# --- the README's agent snippet, and the field's habits --------------------------------------------


@pytest.mark.slow
def test_the_readmes_agent_snippet_runs_from_another_folder_and_a_missing_file_says_so(tmp_path):
    """The snippet worked only from the clone's root: from another folder its relative path met "unreadable
    checkpoint (FileNotFoundError …)". It finds the agents beside the module it imports, and seeds act per call
    (a numpy Generator), so two runs from anywhere print the same return; a missing file reads "no such file"."""
    section = (ROOT / "README.md").read_text().split("## Use a trained agent", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL).group(1)
    assert "seed=rng" in code and "agent.predict(obs, deterministic=True)` returns `(action, None)`" in section
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # as an installed copy is importable from anywhere
    printed = [subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300, check=True).stdout for _ in range(2)]  # fmt: skip
    assert printed[0] == printed[1] and float(printed[0]) > 1000
    with pytest.raises(FileNotFoundError) as missing:
        ppo_pgg_discrete.load_checkpoint("results/discrete/agents/nothing.pt")
    assert (
        str(missing.value) == f"no such checkpoint file: results/discrete/agents/nothing.pt (relative to {Path.cwd()})"
    )


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_predict_is_sb3s_call_and_act_takes_a_seed_of_its_own(kind):
    """Stable-Baselines3's `model.predict(obs, deterministic=True)` -> (action, state) had no counterpart, and `act`
    seeded only through torch's global generator or noise=: a per-call seed (an int or a numpy Generator) draws the
    same actions each time and leaves torch's generator where it was."""
    agent = SCRIPTS[kind].Agent(4, 3)
    obs = np.random.default_rng(0).standard_normal((6, 4))
    action, state = agent.predict(obs, deterministic=True)
    assert state is None and np.array_equal(action, agent.act(obs, 1.0, deterministic=True))
    assert np.array_equal(agent.predict(obs, guidance=2.0)[0].shape, agent.act(obs, 2.0).shape)
    torch_state = torch.get_rng_state()
    assert np.array_equal(agent.act(obs, 1.5, seed=3), agent.act(obs, 1.5, seed=3))
    first, second = np.random.default_rng(7), np.random.default_rng(7)
    assert np.array_equal([agent.act(obs, 1.5, seed=first) for _ in range(3)],
                          [agent.act(obs, 1.5, seed=second) for _ in range(3)])  # fmt: skip
    assert torch.equal(torch.get_rng_state(), torch_state)
    for bad, message in ((-1, "seed must be an integer in [0, 2**64) or a numpy Generator, got -1"),
                         (1.5, "seed must be an integer in [0, 2**64) or a numpy Generator, got 1.5")):  # fmt: skip
        with pytest.raises(ValueError) as refused:
            agent.act(obs, 1.0, seed=bad)
        assert str(refused.value) == message
    with pytest.raises(ValueError, match=r"^pass noise or seed, not both: seed draws the noise$"):
        agent.act(obs[0], 1.0, noise=np.zeros(3), seed=1)


@pytest.mark.slow
def test_compare_paper_with_one_seed_says_no_cell_is_tested_not_alpha_nan(tmp_path):
    """With one seed, compare_paper.md printed "at Holm's first step (α/4 = nan)": no Welch test is possible, and
    the report says so; with seeds enough the sentence is as before."""
    means = {("CartPole-v1", "ppo", 100000, 1.0): [270], ("CartPole-v1", "pgg_g1.1", 100000, 2.0): [100]}
    write_episodes(tmp_path / "one" / "episodes.csv", episode_rows(means))
    plots.generate(plots.Args(sweeps=(str(tmp_path / "one"),), output=str(tmp_path / "o1"), compare_paper=True))
    report = (tmp_path / "o1" / "compare_paper.md").read_text()
    assert "nan" not in report and "= nan" not in report
    assert ("Cell by cell, **no cell is tested**: Welch's t needs two seeds on each side, and ours hold one (the "
            "relative gap's interval above is then a point).") in report  # fmt: skip
    write_episodes(tmp_path / "three" / "episodes.csv", episode_rows(SEED_MEANS))
    plots.generate(plots.Args(sweeps=(str(tmp_path / "three"),), output=str(tmp_path / "o3"), compare_paper=True))
    assert "Holm-corrected over these 12 cells" in (tmp_path / "o3" / "compare_paper.md").read_text()


# --- docs/usage.md, as the code and the logs have it ---------------------------------------------------


def test_usage_says_what_a_cells_name_follows_as_the_code_does(tmp_path, monkeypatch):
    """docs/usage.md said a cell's name "covers every file of code that runs in its episodes" while a helper inside a
    task's package, imported by the package's name, was not followed. The code follows it now (a task's package is
    importable, as `--env-id pk.tasks:...` needs), and the page says so."""
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "__init__.py").write_text("")
    (tmp_path / "mypkg" / "helper.py").write_text("")
    (tmp_path / "mypkg" / "tasks.py").write_text("from mypkg import helper\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert tmp_path / "mypkg" / "helper.py" in cells.imported_files([tmp_path / "mypkg" / "tasks.py"])
    usage = " ".join((ROOT / "docs" / "usage.md").read_text().split())
    assert "covers every file of code that runs in its episodes" in usage and "in a task's package" in usage


def test_usage_gives_the_logged_suites_count_and_the_three_skips_of_a_fresh_clone():
    """docs/usage.md gave "9 min 27 s for 494" (a run with a failure; the suite then collected 495) and one skip,
    where a fresh clone skips three: rliable is not in [dev], the paper's figures lie in ../shared/paper, and a
    MuJoCo video needs a headless renderer."""
    usage = " ".join((ROOT / "docs" / "usage.md").read_text().split())
    found = re.search(r"(\d+) min (\d+) s for the (\d+) of (2026-\d\d-\d\d)", usage)
    minutes, seconds, count, day = found.groups()
    log = (ROOT / "results" / f"run_logs_{day}.txt").read_text()
    counts = re.search(rf"^(?:(\d+) failed, )?(\d+) passed, (\d+) skipped, .*\(0:{int(minutes):02d}:{int(seconds):02d}\)$",
                       log, re.MULTILINE).groups()  # fmt: skip
    assert int(count) == sum(int(n or 0) for n in counts)
    assert "rliable" not in (ROOT / "pyproject.toml").read_text().split("dev = [", 1)[1].split("]", 1)[0]
    assert "In a fresh clone three are skipped" in usage
    assert all(word in usage for word in ("`pip install rliable`", "`../shared/paper`", "`apt-get install libosmesa6`"))


def test_an_agents_export_removes_only_the_agents_an_earlier_export_wrote(tmp_path):
    """reproduce.py's agents folder shares the rule: an export before manifests, which only its README lists,
    loses its stale agents, while a training checkpoint or any other file of the user's under a listed run stays."""
    folder = tmp_path / "agents"
    stale = folder / "cartpole" / "checkpoints"
    checkpoints.export_agent(FORMAT_2, stale / FORMAT_2.name)
    shutil.copy(FORMAT_2, stale / "step_000001024.pt")  # the user's training checkpoint, resume state and all
    (stale / "step_000002048.pt").write_bytes(b"the user's")
    (folder / "README.md").write_text(f"# Trained agents\n\n{agents.README_HEADER}\n|---|---|---|---|---|---|\n"
                                      "| cartpole | CartPole-v1 | pgg_g1.1 | 1 | 512 | `python ppo_pgg_discrete.py` |\n")  # fmt: skip
    agents.export_agents([], folder)
    assert sorted(p.name for p in stale.iterdir()) == ["step_000001024.pt", "step_000002048.pt"]
    assert read_manifest(folder) == {}
