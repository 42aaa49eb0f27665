"""The section "Guidance on a condition, with the condition dropped in training" of "Beyond the paper", and its
figure: classifier-free guidance's recipe on a condition (the command or the goal dropped with probability 0.1 in
updates, both branches trained at γ_train 1, guidance only at test; results/beyond/condition_dropout/run_all.sh)
against the committed sets beside it. beyond/report.py calls `read`, `section` and `figure`; it reads:
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

from beyond.cells import record
from beyond.command import gain, per_seed
from beyond.dropout_goal import goal_part, null_part
from beyond.dropout_sets import Sets
from beyond.dropout_tests import (
    SECTION,
    against_gamma_one,
    against_others,
    falls_and_rises,
    family,
    gaps_of,
    named,
    record_family,
    record_welch,
    seeds_of,
    test_cells,
)
from beyond.sets import COMMAND_DROPOUT, COMMAND_ENV, COMMAND_SEEDS, COMMAND_SET, DROPOUT_FOLDER, GOAL_DROPOUT
from beyond.text import marks, name, seeds_cell
from paper_study.agreement import fmt_p
from paper_study.stats import ALPHA

FIGURE = "condition_dropout.png"


# The command bands: the thirds of the training range, then the commands below and above it.
BANDS = ("low", "middle", "high", "below", "above")


def command_bands(commands: list[float], inside: dict) -> list[tuple[str, list[float]]]:
    """(band, its commands) of the bands that hold a command: the thirds of the training range (its lowest and
    highest command inside), then the commands below and above it."""
    in_range = [c for c in commands if inside[c]]
    low, high = min(in_range), max(in_range)
    third = (high - low) / 3
    chosen = {"low": [c for c in in_range if c < low + third],
              "middle": [c for c in in_range if low + third <= c <= high - third],
              "high": [c for c in in_range if c > high - third],
              "below": [c for c in commands if not inside[c] and c < low],
              "above": [c for c in commands if not inside[c] and c > high]}  # fmt: skip
    return [(name, chosen[name]) for name in BANDS if chosen[name]]


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
    cells = sets.command
    if not any(k[0] == COMMAND_DROPOUT for k in cells):
        return ["", f"**Not run yet:** the dropout set's tracking.csv holds no episode of {COMMAND_DROPOUT}."]
    env, variants = COMMAND_ENV, [v for v in COMMAND_SET if any(k[0] == v for k in cells)]
    gammas, commands = sorted({g for (v, s, g, c) in cells}), sorted({c for (v, s, g, c) in cells})
    bands = command_bands(commands, sets.inside)
    in_range = [c for c in commands if sets.inside[c]]
    gaps = gaps_of(cells, COMMAND_DROPOUT)
    record(values_out, env, COMMAND_DROPOUT, SECTION, "whole", float(not gaps))
    lines = ["", "### The command task", ""]
    if gaps:
        lines += [(f"**Partial set:** {'; '.join(gaps)}. The tables below hold what there is; they are not the set's "
                   "result, and a verdict waits for the whole set."), ""]  # fmt: skip
    lines += [(f"{marks(sets.command_steps, variants)}: eval γ {', '.join(f'{g:g}' for g in gammas)} (a variant's row is absent "
               f"where it was not tracked at that γ); the bands: "
               + "; ".join(f"{band_name} {', '.join(f'{c:g}' for c in chosen)}" for band_name, chosen in bands)
               + " m/s (the training range is "
               f"[{min(in_range):g}, {max(in_range):g}]). Each seed's value is the mean over its episodes and the commands "
               "named, then mean ± 95% CI over seeds.")]  # fmt: skip
    over_range = lambda quantity: lambda v, g: per_seed(cells, v, g, in_range, quantity)
    error = family(against_gamma_one(variants, gammas, over_range("error")))
    step_error = family(against_gamma_one(variants, gammas, over_range("step_error")))
    gains = family(against_gamma_one(variants, gammas, lambda v, g: gain(cells, v, g, in_range)))
    returns = family(against_gamma_one(variants, gammas, over_range("return")))
    for rows, quantity in ((error, "tracking error"), (step_error, "per-step error"), (gains, "gain"),
                           (returns, "return")):  # fmt: skip
        record_family(values_out, env, rows, quantity)
    for variant in variants:
        record(values_out, env, variant, SECTION, "seeds", seeds_of(error, variant))
    lines += ["", ("**Does γ > 1 make the agents follow the command more closely, with and without dropout?** Over the "
                   "training range at each eval γ: the tracking error |mean velocity − command| of each episode (the "
                   "report's), and beside it the reward's per-step error, the mean over the episode of |v_t − command| "
                   "(tracking.csv's `tracking_error`), each against γ = 1 (Holm over each measure's "
                   f"{sum(r['test'] is not None for r in error)} tests apart). A negative change follows more closely."), "",
              ("| variant (null) | seeds | γ | tracking error (m/s) | vs γ = 1 | p (Holm) | detectable | per-step error "
               "(m/s) | vs γ = 1 | p (Holm) | detectable |"), "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for ours, theirs in zip(error, step_error, strict=True):
        lines.append(f"| {name(ours['variant'], COMMAND_SET)} | {len(ours['values'])} | {ours['gamma']:g} | "
                     f"{seeds_cell(ours['values'], 3)} | " + " | ".join(test_cells(ours["test"], 3))
                     + f" | {seeds_cell(theirs['values'], 3)} | " + " | ".join(test_cells(theirs["test"], 3)) + " |")  # fmt: skip
    lines += ["", ("The gain (slope of achieved on commanded velocity over the training range: 1 follows every change "
                   "of command, 0 ignores it) and the return over the range, each against γ = 1 (Holm over each "
                   "measure's tests apart)."), "",
              ("| variant (null) | γ | gain | vs γ = 1 | p (Holm) | detectable | return | vs γ = 1 | p (Holm) | "
               "detectable |"), "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for ours, theirs in zip(gains, returns, strict=True):
        return_cells = test_cells(theirs["test"], 1)
        lines.append(f"| {name(ours['variant'], COMMAND_SET)} | {ours['gamma']:g} | {seeds_cell(ours['values'])} | "
                     + " | ".join(test_cells(ours["test"], 2)) + f" | {seeds_cell(theirs['values'], 1)} | "
                     + " | ".join(return_cells) + " |")  # fmt: skip
    by_band = {}
    for names in (("low", "middle", "high"), ("below", "above")):  # inside the range, outside it: two families
        rows = family([r for band_name, chosen in bands if band_name in names for r in against_gamma_one(
            variants, gammas, lambda v, g, chosen=chosen: per_seed(cells, v, g, chosen, "error"), band=band_name)])  # fmt: skip
        record_family(values_out, env, rows, "tracking error")
        by_band.update({(r["variant"], r["band"], r["gamma"]): r for r in rows})
    family_size = lambda names: sum(r["test"] is not None for r in by_band.values() if r["band"] in names)
    lines += ["", ("**Per band of commands**, since changes of opposite sign cancel in the error over the range: the "
                   "tracking error over each band at each eval γ, and against γ = 1 its change, Holm p and the change "
                   f"one test detects (Holm over the {family_size(('low', 'middle', 'high'))} tests inside the range, "
                   f"and apart over the {family_size(('below', 'above'))} outside it): error (change, p Holm; "
                   "detectable)."), "",
              "| variant (null) | band | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |",
              "|---|---|" + "---|" * len(gammas)]  # fmt: skip
    for variant in variants:
        for band_name, chosen in bands:
            shown = []
            for gamma in gammas:
                r = by_band.get((variant, band_name, gamma))
                if r is None:
                    shown.append("–")
                    continue
                mean = float(np.mean(list(r["values"].values())))
                test = r["test"]
                shown.append(f"{mean:.3f}" if test is None else
                             f"{mean:.3f} ({test['difference']:+.3f}, {fmt_p(test['p_holm'])}; {test['detectable']:.3f})")  # fmt: skip
            lines.append(f"| {name(variant, COMMAND_SET)} | {band_name} ({', '.join(f'{c:g}' for c in chosen)}) | "
                         + " | ".join(shown) + " |")  # fmt: skip
    knob = against_others(variants, gammas, lambda v, g: per_seed(cells, v, g, in_range, "error"), COMMAND_DROPOUT)
    knob_gain = against_others(variants, gammas, lambda v, g: gain(cells, v, g, in_range), COMMAND_DROPOUT)
    record_welch(values_out, env, knob, COMMAND_DROPOUT, "tracking error")
    record_welch(values_out, env, knob_gain, COMMAND_DROPOUT, "gain")
    lines += ["", ("**Does dropping the command give a knob the others lack?** The dropout set's per-seed change from "
                   "γ = 1 against each other variant's, over the training range, in tracking error and in gain: Welch's "
                   f"t test (distinct runs), Holm over the {len(knob)} error tests and apart over the {len(knob_gain)} "
                   "gain tests. A negative error difference, or a positive gain difference, follows the command more "
                   "closely with dropout."), "",
              "| measure | γ | against | dropout's change | its change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for measure, rows in (("tracking error", knob), ("gain", knob_gain)):
        for r in rows:
            lines.append(f"| {measure} | {r['gamma']:g} | {name(r['baseline'], COMMAND_SET)} | {r['mean']:+.3f} | "
                         f"{r['baseline_mean']:+.3f} | {r['mean'] - r['baseline_mean']:+.3f} | {fmt_p(r['p'])} "
                         f"({fmt_p(r['p_holm'])}) | {r['detectable']:.3f} |")  # fmt: skip
    if not gaps:
        lines += command_verdict(error, step_error, gains, by_band, knob, knob_gain)
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
