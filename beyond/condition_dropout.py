"""The section "Guidance on a condition, with the condition dropped in training" of "Beyond the paper":
classifier-free guidance's recipe on a condition (the command or the goal dropped with probability 0.1 in updates,
both branches trained at γ_train 1, guidance only at test; results/beyond/condition_dropout/run_all.sh) against the
committed sets beside it. beyond/report.py reads the sets with dropout_sets.read, writes this module's `section` (its
command part here; the Reacher part and the learned nulls in dropout_goal.py; the numbers in dropout_command.py and
dropout_tests.py) and draws figures.dropout_figure. The files read:
  condition_dropout/command/tracking.csv   the command set with the command dropped (beyond/command_tracking.py)
  command/tracking.csv                     the command null without dropout, the state null and PPO
  condition_dropout/goal_distance.csv      Reacher-v4 with the goal dropped (beyond/goal_distance.py)
  goal_distance.csv                        Reacher-v4's goal null, state null and PPO
  command/, Reacher-v4/, condition_dropout/command/, condition_dropout/Reacher-v4/ learned_null.csv
                                           what each agent's null acts like (beyond/learned_null.py)
A file absent is named in one line and its part gives no number; a set with fewer than COMMAND_SEEDS seeds, or
a cell short of episodes, is marked partial and gets no verdict.

The command task's tests, each a Holm family of its own (all at α = 0.05, each with the difference one test detects
with 80% power, before Holm): each variant's tracking error over the training range at each γ against γ = 1,
paired by seed, measured two ways (the episode's mean velocity's error, the report's tracking error; and the
reward's per-step error, tracking.csv's `tracking_error`); its gain (slope of achieved on commanded velocity); its
return; its error per band of commands (the low, middle and high thirds of the training range); outside the range
(below it, above it); and the dropout set's change from γ = 1 against each other variant's (Welch, distinct runs),
in error and in gain. Reacher-v4: each variant's final distance to the goal at each γ against γ = 1, paired by
seed, and the dropout set's change against the others' (Welch)."""

import numpy as np

from beyond.dropout_command import command_tables, command_values
from beyond.dropout_goal import goal_part, null_part
from beyond.dropout_sets import Sets
from beyond.dropout_tests import (
    cell,
    falls_and_rises,
    named,
    test_cells,
)
from beyond.sets import COMMAND_DROPOUT, COMMAND_SEEDS, COMMAND_SET, DROPOUT_FOLDER, GOAL_DROPOUT
from beyond.text import change_cell, fill, marks, name, seeds_cell
from paper_study.agreement import fmt_p
from paper_study.stats import ALPHA

FIGURE = "condition_dropout.png"


def section(sets: Sets, values_out: list[dict]) -> list[str]:
    """The section's lines, from what `read` found."""
    lines = ["## Guidance on a condition, with the condition dropped in training", "",
             ("Classifier-free guidance trains its unconditional model by dropping the condition at random. The command "
              "null and the goal null above were trained without it (`--cond-dropout 0`, γ_train 1.1), so their "
              "π(a|s, ∅) was never trained to stand for \"no command\" (what it is instead: \"What the learned null "
              "is\", below). These sets drop the condition with probability 0.1 in updates, both branches trained at "
              f"γ_train 1, guidance only at test (results/beyond/{DROPOUT_FOLDER}, `run_all.sh`): the command task with "
              f"`--null-dims 17 --cond-dropout 0.1` ({COMMAND_DROPOUT}), tracked as the command set was, against the "
              "command null without dropout, the state null and PPO (results/beyond/command); Reacher-v4 with "
              f"`--null-dims 4 5 8 9 10 --cond-dropout 0.1` ({GOAL_DROPOUT}), its final distance to the goal against the "
              "goal null without dropout, the state null and PPO (goal_distance.csv). Against the null without "
              "dropout two things change at once: the dropout, and γ_train (1 against 1.1). Every test below is paired "
              "by seed against γ = 1 (t test) or, between variants, Welch's on the per-seed changes from γ = 1; Holm "
              "within each table's family, and beside each the difference one test detects with 80% power at α = "
              "0.05, before Holm, so that a test that finds nothing says how large a change it could have missed.")]  # fmt: skip
    lines += command_part(sets, values_out)
    lines += goal_part(sets, values_out)
    lines += null_part(sets, values_out)
    if any(drawn(sets)):
        lines += ["", ("Tracking error over each band of commands, and Reacher's final distance to the goal, against "
                       "eval γ for the four variants of each task (mean over seeds, 95% CI band):"), "",
                  f"![Tracking error per command band and goal distance against γ, with and without dropout]({FIGURE})"]  # fmt: skip
    return [*lines, ""]


PARTIAL = ("**Partial set:** {gaps}. The tables below hold what there is; they are not the set's result, and a verdict "
           "waits for the whole set.")  # fmt: skip
AT_MARK = ("{marks}: eval γ {gammas:gs} (a variant's row is absent where it was not tracked at that γ); the bands: {bands} "
           "m/s (the training range is [{low:g}, {high:g}]). Each seed's value is the mean over its episodes and the "
           "commands named, then mean ± 95% CI over seeds.")  # fmt: skip
ERRORS = ("**Does γ > 1 make the agents follow the command more closely, with and without dropout?** Over the training "
          "range at each eval γ: the tracking error |mean velocity − command| of each episode (the report's), and beside "
          "it the reward's per-step error, the mean over the episode of |v_t − command| (tracking.csv's "
          "`tracking_error`), each against γ = 1 (Holm over each measure's {tests} tests apart). A negative change "
          "follows more closely.")  # fmt: skip
ERRORS_HEAD = ("| variant (null) | seeds | γ | tracking error (m/s) | vs γ = 1 | p (Holm) | detectable | per-step error "
               "(m/s) | vs γ = 1 | p (Holm) | detectable |\n|---|---|---|---|---|---|---|---|---|---|---|")  # fmt: skip
GAINS = ("The gain (slope of achieved on commanded velocity over the training range: 1 follows every change of command, 0 "
         "ignores it) and the return over the range, each against γ = 1 (Holm over each measure's tests apart).")  # fmt: skip
GAINS_HEAD = ("| variant (null) | γ | gain | vs γ = 1 | p (Holm) | detectable | return | vs γ = 1 | p (Holm) | "
              "detectable |\n|---|---|---|---|---|---|---|---|---|---|")  # fmt: skip
BANDS_TEXT = ("**Per band of commands**, since changes of opposite sign cancel in the error over the range: the tracking "
              "error over each band at each eval γ, and against γ = 1 its change, Holm p and the change one test detects "
              "(Holm over the {inside} tests inside the range, and apart over the {outside} outside it): error (change, "
              "p Holm; detectable).")  # fmt: skip
KNOB = ("**Does dropping the command give a knob the others lack?** The dropout set's per-seed change from γ = 1 against "
        "each other variant's, over the training range, in tracking error and in gain: Welch's t test (distinct runs), "
        "Holm over the {errors} error tests and apart over the {gains} gain tests. A negative error difference, or a "
        "positive gain difference, follows the command more closely with dropout.")  # fmt: skip
KNOB_HEAD = ("| measure | γ | against | dropout's change | its change | difference | p (Holm) | detectable |\n"
             "|---|---|---|---|---|---|---|---|")  # fmt: skip


def command_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """The command task: does γ make the agents trained with the command dropped follow it more closely?"""
    if "command" in sets.absent:
        return ["", (f"**Not run yet:** {sets.absent['command']} does not exist (results/beyond/{DROPOUT_FOLDER}/run_all.sh "
                     f"trains, sweeps and tracks the set): no numbers of the command task with the command dropped.")]  # fmt: skip
    if "command baselines" in sets.absent:
        return [
            "",
            f"**Not comparable:** {sets.absent['command baselines']} does not exist: no baseline to compare with.",
        ]
    if not any(k[0] == COMMAND_DROPOUT for k in sets.command):
        return ["", f"**Not run yet:** the dropout set's tracking.csv holds no episode of {COMMAND_DROPOUT}."]
    t = command_tables(sets.command, sets.inside)
    values_out += command_values(t)
    variants, gammas, bands = t["variants"], t["gammas"], t["bands"]
    lines = ["", "### The command task", ""]
    if t["gaps"]:
        lines += [fill(PARTIAL, gaps="; ".join(t["gaps"])), ""]
    lines.append(fill(AT_MARK, marks=marks(sets.command_steps, variants), gammas=gammas, low=min(t["in_range"]),
                      high=max(t["in_range"]), bands="; ".join(f"{band} {', '.join(f'{c:g}' for c in chosen)}" for band, chosen in bands)))  # fmt: skip
    lines += ["", fill(ERRORS, tests=sum(r["test"] is not None for r in t["error"])), "", ERRORS_HEAD]
    for ours, theirs in zip(t["error"], t["step_error"], strict=True):
        lines.append(f"| {name(ours['variant'], COMMAND_SET)} | {len(ours['values'])} | {ours['gamma']:g} | "
                     f"{seeds_cell(ours['values'], 3)} | " + " | ".join(test_cells(ours["test"], 3))
                     + f" | {seeds_cell(theirs['values'], 3)} | " + " | ".join(test_cells(theirs["test"], 3)) + " |")  # fmt: skip
    lines += ["", GAINS, "", GAINS_HEAD]
    for ours, theirs in zip(t["gains"], t["returns"], strict=True):
        lines.append(f"| {name(ours['variant'], COMMAND_SET)} | {ours['gamma']:g} | {seeds_cell(ours['values'])} | "
                     + " | ".join(test_cells(ours["test"], 2)) + f" | {seeds_cell(theirs['values'], 1)} | "
                     + " | ".join(test_cells(theirs["test"], 1)) + " |")  # fmt: skip
    inside, outside = (sum(r["test"] is not None for r in rows) for rows in t["band_families"])
    lines += ["", fill(BANDS_TEXT, inside=inside, outside=outside), "",
              "| variant (null) | band | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |", "|---|---|" + "---|" * len(gammas)]  # fmt: skip
    for variant in variants:
        for band, chosen in bands:
            shown = [change_cell(*cell(t["by_band"].get((variant, band, gamma))), 3) for gamma in gammas]
            lines.append(
                f"| {name(variant, COMMAND_SET)} | {band} ({', '.join(f'{c:g}' for c in chosen)}) | "
                + " | ".join(shown)
                + " |"
            )
    lines += ["", fill(KNOB, errors=len(t["knob"]), gains=len(t["knob_gain"])), "", KNOB_HEAD]
    for measure, rows in (("tracking error", t["knob"]), ("gain", t["knob_gain"])):
        lines += [f"| {measure} | {r['gamma']:g} | {name(r['baseline'], COMMAND_SET)} | {r['mean']:+.3f} | "
                  f"{r['baseline_mean']:+.3f} | {r['mean'] - r['baseline_mean']:+.3f} | {fmt_p(r['p'])} "
                  f"({fmt_p(r['p_holm'])}) | {r['detectable']:.3f} |" for r in rows]  # fmt: skip
    if not t["gaps"]:
        lines += command_verdict(t["error"], t["step_error"], t["gains"], t["by_band"], t["knob"], t["knob_gain"])
    return lines


def command_verdict(error, step_error, gains, by_band, knob, knob_gain) -> list[str]:
    """What the command part's tests say of the dropout set, from their results alone."""
    ours = COMMAND_DROPOUT
    above, falls, rises = falls_and_rises(error, ours)
    parts = [(f"**What these tests say, and no more.** With the command dropped in training, {len(falls)} of the "
              f"{len(above)} tests of a γ above 1 against γ = 1 find a significant fall in the tracking error over the "
              f"range after Holm{named(falls)}, and {len(rises)} a rise{named(rises)}")]  # fmt: skip
    if above:
        best = min(above, key=lambda r: r["test"]["difference"])
        parts.append(f"; its most negative change is {best['test']['difference']:+.3f} m/s at γ {best['gamma']:g} (p "
                     f"{fmt_p(best['test']['p'])}, Holm {fmt_p(best['test']['p_holm'])}; one test detects "
                     f"{best['test']['detectable']:.3f})")  # fmt: skip
    step_above, step_falls, step_rises = falls_and_rises(step_error, ours)
    parts.append(f". The per-step error: {len(step_falls)} falls and {len(step_rises)} rises of {len(step_above)}")
    gain_above, gain_falls, gain_rises = falls_and_rises(gains, ours)
    at_one = next((r for r in gains if r["variant"] == ours and r["gamma"] == 1.0), None)
    if at_one is not None:
        parts.append(f". The gain at γ = 1 is {np.mean(list(at_one['values'].values())):.2f}; of the {len(gain_above)} "
                     f"tests above 1, {len(gain_rises)} find it rise{named(gain_rises, '')} and {len(gain_falls)} fall"
                     f"{named(gain_falls, '')}")  # fmt: skip
    band_rows = [r for r in by_band.values() if r["band"] in ("low", "middle", "high")]
    band_above, band_falls, band_rises = falls_and_rises(band_rows, ours)
    parts.append(f". Per band inside the range: {len(band_falls)} falls{named(band_falls)} and {len(band_rises)} rises"
                 f"{named(band_rises)} of {len(band_above)} tests above 1")  # fmt: skip
    for measure, rows in (("error", knob), ("gain", knob_gain)):
        tests = [r for r in rows if r["gamma"] > 1]
        differing = [r for r in tests if r["p_holm"] < ALPHA]
        parts.append(f". Against the other variants above γ = 1, in {measure}: {len(differing)} of {len(tests)} "
                     "differences significant after Holm" + "".join(
                         f"; at γ {r['gamma']:g} against {name(r['baseline'], COMMAND_SET)} the dropout set's change "
                         f"{r['mean']:+.3f} against {r['baseline_mean']:+.3f} (Holm p {fmt_p(r['p_holm'])})"
                         for r in differing))  # fmt: skip
    outside = [r for r in by_band.values() if r["band"] in ("below", "above") and r["variant"] == ours
               and r["test"] is not None]  # fmt: skip
    significant = [r for r in outside if r["test"]["p_holm"] < ALPHA]
    if outside:
        detectable = [r["test"]["detectable"] for r in outside]
        parts.append(f". Outside the training range, {len(significant)} of its {len(outside)} tests find a change after "
                     f"Holm{named(significant)}; one test detects {min(detectable):.3f} to {max(detectable):.3f} m/s "
                     "before Holm")  # fmt: skip
    parts.append(f". What they cannot say: a change smaller than the detectable columns (with {COMMAND_SEEDS} seeds, "
                 "before Holm: after it, more is needed), the effect of the dropout apart from γ_train's, anything of "
                 "another task or probability of dropout.")  # fmt: skip
    return ["", "".join(parts)]


def drawn(sets: Sets) -> tuple[bool, bool]:
    """Whether the figure has a command panel and a goal panel: the dropout set's numbers, and its baselines'."""
    return (any(k[0] == COMMAND_DROPOUT for k in sets.command) and "command baselines" not in sets.absent,
            any(v == GOAL_DROPOUT for v, g in sets.goal) and "goal baselines" not in sets.absent)  # fmt: skip
