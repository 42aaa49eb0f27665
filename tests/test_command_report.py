"""The command task's section of "Beyond the paper" (beyond/command.py, beyond/command_text.py), on a synthetic set: the real
one is trained by results/beyond/command/run_all.sh."""

import csv

import numpy as np
import pytest
from conftest import ROOT  # noqa: F401  (puts the repository on sys.path)

from beyond import command_text, figures
from beyond import sets as beyond_sets
from beyond.command_tracking import COLUMNS
from paper_study import agreement
from paper_study import stats as study_stats
from pgg_utils.files import write_csv_atomic

GAMMAS, COMMANDS = (0.5, 1.0, 2.0), (-0.5, 0.0, 1.0, 2.0, 3.0)
ENV = beyond_sets.COMMAND_ENV


def achieved(variant: str, seed: int, gamma: float, command: float, episode: int) -> float:
    """A synthetic agent: it follows 60% of the command, plus a seed's offset; under the command null γ scales how
    much of the command it follows (the knob), the other nulls ignore γ."""
    follows = 0.6 * (gamma if variant == beyond_sets.COMMAND_NULL else 1.0)
    return min(follows * command, 2.2) + 0.05 * seed + 0.01 * episode + 0.02 * np.sin(3 * seed + 2 * gamma + command)


def tracking_rows(seeds=range(1, 6), skip=()) -> list[dict]:
    rows = []
    for variant in beyond_sets.COMMAND_VARIANTS:
        for seed in seeds:
            for gamma in GAMMAS:
                for command in COMMANDS:
                    if (variant, seed, gamma, command) in skip:
                        continue
                    for episode in range(2):
                        velocity = achieved(variant, seed, gamma, command, episode)
                        rows.append({"env_id": ENV, "variant": variant, "run": f"r{seed}", "seed": seed,
                                     "step": 1_000_000, "eval_guidance": gamma, "command": command,
                                     "in_training_range": "yes" if 0 <= command <= 2 else "no", "episode": episode,
                                     "episode_seed": 30_000 + episode, "return": 1000 * (command - abs(velocity - command)),
                                     "length": 1000, "mean_velocity": velocity, "velocity_error": velocity - command,
                                     "tracking_error": abs(velocity - command), "checkpoint_sha1": "x",
                                     "task_sha1": "y"})  # fmt: skip
    return rows


def section(tmp_path, rows) -> tuple[str, dict]:
    folder = tmp_path / "beyond"
    if rows is not None:
        write_csv_atomic(folder / "command" / "tracking.csv", COLUMNS, rows)
    values = []
    text = "\n".join(command_text.command_section(folder, values))
    return text, {(v["variant"], v["baseline"], v["quantity"]): v["value"] for v in values}


def test_the_section_measures_tracking_against_gamma_and_tests_each_gamma_against_one(tmp_path):
    """In range (commands 0, 1, 2): the command null's error at γ 2 is its seeds' mean |achieved − commanded|, its
    change from γ = 1 is tested paired by seed, and the knob test finds it against the nulls that ignore γ; the gain
    (slope of achieved on commanded velocity) is 0.6·γ under the command null, 0.6 under the others."""
    text, values = section(tmp_path, tracking_rows())
    assert "Partial set" not in text and "Not run yet" not in text
    in_range = [0.0, 1.0, 2.0]
    errors = {seed: np.mean([abs(np.mean([achieved("pgg_g1.1_null17", seed, 2.0, c, e) for e in range(2)]) - c)
                             for c in in_range]) for seed in range(1, 6)}  # fmt: skip
    assert values[("pgg_g1.1_null17", "", "tracking error at γ 2")] == pytest.approx(np.mean(list(errors.values())))
    assert values[("pgg_g1.1_null17", "", "gain at γ 2")] == pytest.approx(1.0, abs=0.15)  # 1.2, capped at 2.2
    assert values[("pgg_g1.1_null17", "γ 1", "tracking error change at γ 2")] < 0
    assert values[("ppo", "", "gain at γ 2")] == pytest.approx(0.6, abs=0.03)
    # the command null's error moves with γ (away from 60% of the command: down at γ 2, up at γ 0.5)
    assert values[("pgg_g1.1_null17", "γ 1", "tracking error change at γ 0.5")] > 0
    assert values[("pgg_g1.1_null17", "ppo", "knob difference at γ 0.5")] > 0
    assert "**Does the command null give a knob" in text and "| above (3) |" in text and "| below (-0.5) |" in text
    assert values[("", "command", "whole")] == 1.0


def test_a_partial_set_says_so_and_is_not_tabled_as_whole(tmp_path):
    """A variant with 4 of 5 seeds, or a cell missing, makes the section say what is missing before any table."""
    text, values = section(tmp_path, tracking_rows(seeds=range(1, 5)))
    assert "**Partial set:**" in text and "4 of 5 seeds" in text and values[("", "command", "whole")] == 0.0
    assert text.index("Partial set") < text.index("| variant (null) |")
    text, _ = section(tmp_path, tracking_rows(skip={("pgg_g1.1", 3, 2.0, 3.0)}))
    assert "**Partial set:**" in text and "cells missing or short of 2 episodes (seed 3)" in text


def test_the_verdict_counts_what_the_tests_found_and_waits_for_a_whole_set(tmp_path):
    """The verdict paragraph counts the γ > 1 tests whose error falls after Holm, names the largest fall and the
    command null's significant differences from the other nulls, all as the tables' values give them; a partial
    set gets no verdict."""
    text, values = section(tmp_path, tracking_rows())
    verdict = next(line for line in text.splitlines() if line.startswith("**What these tests say, and no more.**"))
    above = [(v, g) for v in beyond_sets.COMMAND_VARIANTS for g in GAMMAS if g > 1]
    falls = [(v, g) for v, g in above if values[(v, "γ 1", f"tracking error change at γ {g:g}")] < 0
             and values[(v, "γ 1", f"tracking error p Holm at γ {g:g}")] < study_stats.ALPHA]  # fmt: skip
    assert f"{len(falls)} of the {len(above)} tests of a γ above 1" in verdict
    largest = -values[("pgg_g1.1_null17", "γ 1", "tracking error change at γ 2")]
    assert (
        f"the largest fall is {largest:.3f} m/s (PGG, γ_train = 1.1, null on dims 17 (command null) at γ 2" in verdict
    )
    assert "against the other nulls' below γ = 1: 2 of 2 differences significant" in verdict
    text, _ = section(tmp_path, tracking_rows(seeds=range(1, 5)))
    assert "What these tests say" not in text


def test_a_missing_set_is_named_and_gives_no_numbers(tmp_path):
    text, values = section(tmp_path, None)
    assert "**Not run yet:**" in text and values == {}


def test_the_figure_draws_a_line_per_gamma_in_a_panel_per_variant(tmp_path, monkeypatch):
    lines = []
    real_plot = figures.plt.Axes.plot
    monkeypatch.setattr(
        figures.plt.Axes, "plot", lambda ax, *a, **k: lines.append(k.get("label")) or real_plot(ax, *a, **k)
    )
    section(tmp_path, tracking_rows())
    path = tmp_path / "fig.png"
    assert figures.command_figure(tmp_path / "beyond", path) and path.stat().st_size > 0
    assert sorted(filter(None, lines)) == sorted(f"γ = {g:g}" for g in GAMMAS for _ in range(3))
    with open(tmp_path / "beyond" / "command" / "tracking.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 3 * 5 * 3 * 5 * 2


def test_the_tests_outside_the_range_say_what_they_can_detect(tmp_path):
    """Each test outside the training range carries the change it detects with 80% power (the paired test's, before
    Holm), in its cell and in report_values.csv, and the verdict gives their span: a test that finds nothing says
    how large a change it could have missed."""
    text, values = section(tmp_path, tracking_rows())
    detectable = {(variant, q): v for (variant, baseline, q), v in values.items() if baseline == "γ 1"
                  and q.startswith("tracking error above the range detectable")}  # fmt: skip
    assert len(detectable) == 3 * 2 and all(v > 0 for v in detectable.values())
    change = values[("ppo", "γ 1", "tracking error above the range change at γ 2")]
    p_holm = values[("ppo", "γ 1", "tracking error above the range p Holm at γ 2")]
    shown = values[("ppo", "γ 1", "tracking error above the range detectable at γ 2")]
    assert f"({change:+.3f}, {agreement.fmt_p(p_holm)}; {shown:.3f})" in text
    every = [v for (_, b, q), v in values.items() if b == "γ 1" and "the range detectable" in q]
    verdict = next(line for line in text.splitlines() if line.startswith("**What these tests say, and no more.**"))
    assert f"one test there detects {min(every):.3f} to {max(every):.3f} m/s before Holm" in verdict
    assert "none is computed" not in verdict


def test_the_section_says_how_fast_agents_run_at_the_top_of_the_range(tmp_path):
    """At γ = 1 and the largest command inside the range (2), the mean achieved velocity over every agent, and per
    variant, from the episodes: whether the agents cover the range the tests above it presume."""
    text, values = section(tmp_path, tracking_rows())
    speeds = {v: [np.mean([achieved(v, s, 1.0, 2.0, e) for e in range(2)]) for s in range(1, 6)]
              for v in beyond_sets.COMMAND_VARIANTS}  # fmt: skip
    every = [x for v in speeds for x in speeds[v]]
    assert values[("", "command", "velocity at command 2 at γ 1")] == pytest.approx(np.mean(every))
    assert values[("ppo", "", "velocity at command 2 at γ 1")] == pytest.approx(np.mean(speeds["ppo"]))
    assert (
        f"run at {np.mean(every):.2f} m/s on average ({min(every):.2f} to {max(every):.2f} over the 15 agents" in text
    )


def test_the_task_text_states_what_the_null_is_and_how_the_task_differs_from_the_literatures(tmp_path):
    """The command null trained without dropout is not called command-agnostic, and the task's differences from the
    meta-RL literature's velocity task (hidden command, control cost, episode length) are stated."""
    text, _ = section(tmp_path, tracking_rows())
    assert "command-agnostic" not in text and "acts as the policy at one fixed pseudo-command" in text
    assert "the velocity is hidden and inferred from reward, the control cost is 0.05·Σa²" in text
