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

import csv
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from beyond.report import (
    COMMAND_ENV,
    COMMAND_FOLDER,
    COMMAND_NULL,
    COMMAND_SEEDS,
    DROPOUT_FOLDER,
    DROPOUT_VARIANTS,
    band,
    paired_test,
    panels,
    record,
    save,
    seeds_cell,
    welch_of,
)
from paper_study.agreement import fmt_p, step_label
from paper_study.paper import paper_name
from paper_study.stats import ALPHA, holm

GOAL_ENV = "Reacher-v4"
COMMAND_DROPOUT = next(v for v, folder in DROPOUT_VARIANTS.items() if folder == COMMAND_FOLDER)
GOAL_DROPOUT = next(v for v, folder in DROPOUT_VARIANTS.items() if folder == GOAL_ENV)
# Each task's variants in the tables' order, with the null each is guided by.
COMMAND_SET = {COMMAND_DROPOUT: "command dropped", COMMAND_NULL: "command null", "pgg_g1.1": "state null",
               "ppo": "untrained null"}  # fmt: skip
GOAL_SET = {GOAL_DROPOUT: "goal dropped", "pgg_g1.1_goal": "goal null", "pgg_g1.1": "state null",
            "ppo": "untrained null"}  # fmt: skip
SECTION = "condition dropout"  # report_values.csv's `baseline` of this section's rows, apart from the others'
FIGURE = "condition_dropout.png"
LEARNED_NULL = "learned_null.csv"
# The command bands: the thirds of the training range, then the commands below and above it.
BANDS = ("low", "middle", "high", "below", "above")


@dataclass
class Sets:
    """What the section reads: the command task's cells {(variant, seed, γ, command): {field: mean over episodes,
    "episodes": n}} at each file's last step, {command: inside the training range}, {variant: step}; Reacher's
    {(variant, γ): {seed: (mean final distance, episodes)}} and {variant: step}; the learned nulls' rows; and a
    line per file absent."""

    command: dict = field(default_factory=dict)
    inside: dict = field(default_factory=dict)
    command_steps: dict = field(default_factory=dict)
    goal: dict = field(default_factory=dict)
    goal_steps: dict = field(default_factory=dict)
    nulls: list = field(default_factory=list)
    absent: dict = field(default_factory=dict)


def read_tracking_into(sets: Sets, path: Path, variants) -> None:
    """The cells of `variants` in one tracking.csv at its last step, into `sets`."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["variant"] in variants]
    if not rows:
        return
    last = max(int(r["step"]) for r in rows)
    episodes = defaultdict(list)
    for r in rows:
        sets.inside[float(r["command"])] = r["in_training_range"] == "yes"
        if int(r["step"]) == last:
            episodes[(r["variant"], int(r["seed"]), float(r["eval_guidance"]), float(r["command"]))].append(
                (
                    abs(float(r["velocity_error"])),
                    float(r["tracking_error"]),
                    float(r["mean_velocity"]),
                    float(r["return"]),
                )
            )
    for key, values in episodes.items():
        means = np.mean(values, axis=0)
        sets.command[key] = {"error": means[0], "step_error": means[1], "velocity": means[2], "return": means[3],
                             "episodes": len(values)}  # fmt: skip
        sets.command_steps[key[0]] = last


def read_goal_into(sets: Sets, path: Path, variants) -> None:
    """Reacher's final distances of `variants` in one goal_distance.csv at each variant's last step, into `sets`."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["env_id"] == GOAL_ENV and r["variant"] in variants]
    last = {}
    for r in rows:
        last[r["variant"]] = max(last.get(r["variant"], 0), int(r["step"]))
    episodes = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if int(r["step"]) == last[r["variant"]]:
            episodes[(r["variant"], float(r["eval_guidance"]))][int(r["seed"])].append(float(r["final_distance"]))
    for key, seeds in episodes.items():
        sets.goal[key] = {seed: (float(np.mean(d)), len(d)) for seed, d in sorted(seeds.items())}
    sets.goal_steps.update(last)


def read(folder: Path) -> Sets:
    """Every file the section reads, from `folder` (results/beyond); the absent ones named."""
    sets, dropout = Sets(), folder / DROPOUT_FOLDER
    sources = (
        ("command", dropout / COMMAND_FOLDER / "tracking.csv", {COMMAND_DROPOUT}, read_tracking_into),
        ("command baselines", folder / COMMAND_FOLDER / "tracking.csv", set(COMMAND_SET) - {COMMAND_DROPOUT},
         read_tracking_into),
        ("goal", dropout / "goal_distance.csv", {GOAL_DROPOUT}, read_goal_into),
        ("goal baselines", folder / "goal_distance.csv", set(GOAL_SET) - {GOAL_DROPOUT}, read_goal_into),
    )  # fmt: skip
    for name, path, variants, reader in sources:
        if path.exists():
            reader(sets, path, variants)
        else:
            sets.absent[name] = path.relative_to(folder)
    for path in (folder / COMMAND_FOLDER, folder / GOAL_ENV, dropout / COMMAND_FOLDER, dropout / GOAL_ENV):
        if (path / LEARNED_NULL).exists():
            with open(path / LEARNED_NULL, newline="") as f:
                sets.nulls += list(csv.DictReader(f))
    return sets


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


def per_seed(cells: dict, variant: str, gamma: float, commands: list[float], quantity: str) -> dict:
    """{seed: the mean over `commands` of a cell field} for the seeds that hold every one of those cells."""
    seeds = sorted({s for (v, s, g, c) in cells if v == variant})
    return {s: float(np.mean([cells[(variant, s, gamma, c)][quantity] for c in commands])) for s in seeds
            if all((variant, s, gamma, c) in cells for c in commands)}  # fmt: skip


def gain(cells: dict, variant: str, gamma: float, commands: list[float]) -> dict:
    """{seed: the slope of achieved on commanded velocity over `commands`}: 1 follows every change of command."""
    seeds = sorted({s for (v, s, g, c) in cells if v == variant})
    return {s: float(np.polyfit(commands, [cells[(variant, s, gamma, c)]["velocity"] for c in commands], 1)[0])
            for s in seeds if all((variant, s, gamma, c) in cells for c in commands)}  # fmt: skip


def set_holm(tests: list[dict | None]) -> None:
    """Holm over one family: the tests that were made (None where a side had too few seeds)."""
    made = [t for t in tests if t is not None]
    for test, p_holm in zip(made, holm([t["p"] for t in made])):
        test["p_holm"] = p_holm


def against_gamma_one(variants, gammas, measure, **labels) -> list[dict]:
    """Each variant's {seed: value} at each γ it was measured at (measure(variant, γ)), each γ ≠ 1 tested against
    γ = 1 paired by seed; `labels` added to every row. The caller sets Holm over the family (`set_holm`)."""
    rows = []
    for variant in variants:
        reference = measure(variant, 1.0)
        for gamma in gammas:
            if values := measure(variant, gamma):
                rows.append({"variant": variant, "gamma": gamma, "values": values, **labels,
                             "test": None if gamma == 1.0 else paired_test(values, reference)})  # fmt: skip
    return rows


def family(rows: list[dict]) -> list[dict]:
    """`rows` (against_gamma_one's) as one Holm family."""
    set_holm([r["test"] for r in rows])
    return rows


def against_others(variants, gammas, measure, ours: str) -> list[dict]:
    """A family: `ours`'s per-seed change from γ = 1 against each other variant's at each γ ≠ 1 both were measured
    at, Welch's t test (distinct runs); Holm over the family."""
    reference = {variant: measure(variant, 1.0) for variant in variants}
    change = lambda variant, gamma: {s: v - reference[variant][s] for s, v in measure(variant, gamma).items()
                                     if s in reference[variant]}  # fmt: skip
    rows = []
    for gamma in (g for g in gammas if g != 1.0):
        mine = change(ours, gamma)
        for baseline in (v for v in variants if v != ours):
            theirs = change(baseline, gamma)
            if len(mine) >= 2 and len(theirs) >= 2:
                rows.append({"gamma": gamma, "baseline": baseline,
                             **welch_of(list(mine.values()), list(theirs.values()))})  # fmt: skip
    set_holm(rows)
    return rows


def test_cells(test: dict | None, digits: int) -> list[str]:
    """A paired test's change, p (Holm) and detectable difference, as the tables show them."""
    if test is None:
        return ["–", "–", "–"]
    return [f"{test['difference']:+.{digits}f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
            f"{test['detectable']:.{digits}f}"]  # fmt: skip


def record_family(values_out: list, env: str, rows: list[dict], quantity: str) -> None:
    """A family's values and tests into report_values.csv: the mean over seeds at each γ, and against γ = 1 its
    change, p, Holm p and detectable difference (a band's rows name their band after `quantity`)."""
    for r in rows:
        measured = f"{quantity} {r['band']}" if "band" in r else quantity
        record(values_out, env, r["variant"], SECTION, f"{measured} at γ {r['gamma']:g}",
               np.mean(list(r["values"].values())))  # fmt: skip
        if (test := r["test"]) is not None:
            for kind, key in (("change", "difference"), ("p", "p"), ("p Holm", "p_holm"), ("detectable", "detectable")):
                record(values_out, env, r["variant"], f"{SECTION} vs γ 1", f"{measured} {kind} at γ {r['gamma']:g}",
                       test[key])  # fmt: skip


def record_welch(values_out: list, env: str, rows: list[dict], ours: str, quantity: str) -> None:
    for r in rows:
        for name, value in (("change", r["mean"]), ("baseline's change", r["baseline_mean"]),
                            ("difference", r["mean"] - r["baseline_mean"]), ("p", r["p"]), ("p Holm", r["p_holm"]),
                            ("detectable", r["detectable"])):  # fmt: skip
            record(values_out, env, ours, f"{SECTION} vs {r['baseline']}", f"{quantity} {name} at γ {r['gamma']:g}",
                   value)  # fmt: skip


def gaps_of(cells: dict, variant: str) -> list[str]:
    """What a variant's set lacks to be whole: COMMAND_SEEDS seeds, each at every (γ, command) any seed has, with as
    many episodes as the fullest cell; [] where it is whole."""
    mine = {k: v for k, v in cells.items() if k[0] == variant}
    grid = {(g, c) for (v, s, g, c) in mine}
    episodes = max((cell["episodes"] for cell in mine.values()), default=0)
    seeds = sorted({s for (v, s, g, c) in mine})
    gaps = [f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds"] if len(seeds) < COMMAND_SEEDS else []
    short = sorted({s for s in seeds for g, c in grid if mine.get((variant, s, g, c), {"episodes": 0})["episodes"]
                    < episodes})  # fmt: skip
    if short:
        gaps.append(f"{paper_name(variant)}: cells missing or short of {episodes} episodes "
                    f"({', '.join(f'seed {s}' for s in short)})")  # fmt: skip
    return gaps


def goal_gaps(goal: dict, variant: str, gammas: list[float]) -> list[str]:
    """What Reacher's dropout set lacks to be whole: COMMAND_SEEDS seeds at every γ the other sets were scored at,
    each with as many episodes as the fullest cell."""
    seeds = sorted({s for (v, g), by_seed in goal.items() if v == variant for s in by_seed})
    episodes = max((n for (v, g), by_seed in goal.items() if v == variant for _, n in by_seed.values()), default=0)
    gaps = [f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds"] if len(seeds) < COMMAND_SEEDS else []
    short = sorted({s for s in seeds for g in gammas if goal.get((variant, g), {}).get(s, (0, 0))[1] < episodes})
    if short:
        gaps.append(f"{paper_name(variant)}: γ cells missing or short of {episodes} episodes "
                    f"({', '.join(f'seed {s}' for s in short)})")  # fmt: skip
    return gaps


def marks(steps: dict, variants: list[str]) -> str:
    """ "At 1M" where every variant's last mark is one step, else each variant's."""
    if len({steps[v] for v in variants}) == 1:
        return f"At {step_label(steps[variants[0]])}"
    return (
        "At each variant's last mark (" + "; ".join(f"{paper_name(v)}: {step_label(steps[v])}" for v in variants) + ")"
    )


def name(variant: str, nulls: dict) -> str:
    return f"{paper_name(variant)} ({nulls[variant]})"


def seeds_of(values: list[dict], variant: str) -> int:
    return max((len(r["values"]) for r in values if r["variant"] == variant), default=0)


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


def falls_and_rises(rows: list[dict], variant: str) -> tuple[list[dict], list[dict], list[dict]]:
    """A variant's tests of a γ above 1 in a family, and those of them that fall and rise significantly after Holm."""
    above = [r for r in rows if r["variant"] == variant and r["gamma"] > 1 and r["test"] is not None]
    significant = [r for r in above if r["test"]["p_holm"] < ALPHA]
    return above, [r for r in significant if r["test"]["difference"] < 0], [r for r in significant
                                                                           if r["test"]["difference"] > 0]  # fmt: skip


def named(rows: list[dict], unit: str = " m/s", digits: int = 3) -> str:
    """The tests of `rows`, in parentheses: γ (band), change, Holm p; nothing for none."""
    tests = [f"γ {r['gamma']:g}{' ' + r['band'] if 'band' in r else ''} {r['test']['difference']:+.{digits}f}{unit}, "
             f"Holm p {fmt_p(r['test']['p_holm'])}" for r in rows]  # fmt: skip
    return f" ({'; '.join(tests)})" if tests else ""


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


def goal_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """Reacher-v4: does γ bring the agents trained with the goal dropped closer to the goal?"""
    if "goal" in sets.absent or not any(v == GOAL_DROPOUT for v, g in sets.goal):
        where = sets.absent.get("goal", f"{DROPOUT_FOLDER}/goal_distance.csv")
        return ["", (f"**Not run yet:** {where} holds no episode of {GOAL_DROPOUT} (results/beyond/{DROPOUT_FOLDER}/"
                     "run_all.sh trains, sweeps and scores the set): no numbers of Reacher-v4 with the goal dropped.")]  # fmt: skip
    if "goal baselines" in sets.absent:
        return ["", f"**Not comparable:** {sets.absent['goal baselines']} does not exist: no baseline to compare with."]
    env, goal = GOAL_ENV, sets.goal
    variants = [v for v in GOAL_SET if any(k[0] == v for k in goal)]
    gammas = sorted({g for (v, g) in goal})
    measure = lambda v, g: {s: d for s, (d, _) in goal.get((v, g), {}).items()}
    gaps = goal_gaps(goal, GOAL_DROPOUT, sorted({g for (v, g) in goal if v != GOAL_DROPOUT}))
    record(values_out, env, GOAL_DROPOUT, SECTION, "whole", float(not gaps))
    lines = ["", "### Reacher-v4, the goal dropped", ""]
    if gaps:
        lines += [(f"**Partial set:** {'; '.join(gaps)}. The tables below hold what there is; they are not the set's "
                   "result, and a verdict waits for the whole set."), ""]  # fmt: skip
    distance = family(against_gamma_one(variants, gammas, measure))
    record_family(values_out, env, distance, "final distance")
    for variant in variants:
        record(values_out, env, variant, SECTION, "seeds", seeds_of(distance, variant))
    lines += [(f"{marks(sets.goal_steps, variants)}, the final distance to the goal (goal_distance.csv: the last observation's "
               "fingertip to target, the sweep's episodes), mean over seeds of the per-seed mean over episodes, and "
               f"against γ = 1 its change, Holm p (over these {sum(r['test'] is not None for r in distance)} tests) and "
               "the change one test detects: distance (change, p Holm; detectable); lower is closer."), "",
              "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |",
              "|---|---|" + "---|" * len(gammas)]  # fmt: skip
    at = {(r["variant"], r["gamma"]): r for r in distance}
    for variant in variants:
        shown = []
        for gamma in gammas:
            r = at.get((variant, gamma))
            if r is None:
                shown.append("–")
                continue
            mean, test = float(np.mean(list(r["values"].values()))), r["test"]
            shown.append(f"{mean:.4f}" if test is None else
                         f"{mean:.4f} ({test['difference']:+.4f}, {fmt_p(test['p_holm'])}; {test['detectable']:.4f})")  # fmt: skip
        lines.append(f"| {name(variant, GOAL_SET)} | {seeds_of(distance, variant)} | " + " | ".join(shown) + " |")
    knob = against_others(variants, gammas, measure, GOAL_DROPOUT)
    record_welch(values_out, env, knob, GOAL_DROPOUT, "final distance")
    lines += ["", ("The dropout set's per-seed change in distance from γ = 1 against each other variant's: Welch's t "
                   f"test, Holm over these {len(knob)} tests; a negative difference comes closer with dropout."), "",
              "| γ | against | dropout's change | its change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in knob:
        lines.append(f"| {r['gamma']:g} | {name(r['baseline'], GOAL_SET)} | {r['mean']:+.4f} | {r['baseline_mean']:+.4f} | "
                     f"{r['mean'] - r['baseline_mean']:+.4f} | {fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | "
                     f"{r['detectable']:.4f} |")  # fmt: skip
    if not gaps:
        above, falls, rises = falls_and_rises(distance, GOAL_DROPOUT)
        parts = [(f"**What these tests say, and no more.** With the goal dropped in training, {len(falls)} of the "
                  f"{len(above)} tests of a γ above 1 against γ = 1 find a significant fall in the final distance after "
                  f"Holm{named(falls, ' m', 4)}, and {len(rises)} a rise{named(rises, ' m', 4)}")]  # fmt: skip
        if above:
            best = min(above, key=lambda r: r["test"]["difference"])
            parts.append(f"; its most negative change is {best['test']['difference']:+.4f} m at γ {best['gamma']:g} (Holm p "
                         f"{fmt_p(best['test']['p_holm'])}; one test detects {best['test']['detectable']:.4f})")  # fmt: skip
        differing = [r for r in knob if r["p_holm"] < ALPHA]
        parts.append(f". Against the other variants: {len(differing)} of {len(knob)} differences in change significant "
                     "after Holm" + "".join(f"; at γ {r['gamma']:g} against {name(r['baseline'], GOAL_SET)} the dropout "
                                            f"set's change {r['mean']:+.4f} m against {r['baseline_mean']:+.4f} (Holm p "
                                            f"{fmt_p(r['p_holm'])})" for r in differing) + ".")  # fmt: skip
        lines += ["", "".join(parts)]
    return lines


def null_part(sets: Sets, values_out: list[dict]) -> list[str]:
    """What each condition null acts like: the command (goal) whose conditional policy is closest to it."""
    lines = ["", "### What the learned null is", "",
             ("For each agent at its last mark, the command (Reacher: the goal position) whose conditional policy "
              "π(a|s, c) is closest to π(a|s, ∅) in mean KL over the agent's own states at γ = 1 "
              "(`beyond/learned_null.py`: 5,000 states; a grid of commands from −1 to 4 m/s by 0.01, of goals on "
              "a 0.01 m lattice of [−0.25, 0.25]²). Beside it the KL there and the KL to the states' own condition "
              "(what guidance moves away from), and the median over states of how far each state's own closest "
              "condition lies from it: a null that is the policy at one fixed condition has a KL near 0 there and its "
              "states' closest conditions bunched on it; a condition-agnostic null does not.")]  # fmt: skip
    sets_of = ((COMMAND_ENV, "command task", COMMAND_SET, (COMMAND_DROPOUT, COMMAND_NULL), "m/s"),
               (GOAL_ENV, GOAL_ENV, GOAL_SET, (GOAL_DROPOUT, "pgg_g1.1_goal"), "m"))  # fmt: skip
    table = ["", ("| task | variant (null) | seeds | closest condition, per seed | mean | KL there | KL to the own "
                  "condition | per-state spread |"), "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    missing = []
    readings = []
    for env, task, nulls, variants, unit in sets_of:
        for variant in variants:
            rows = [r for r in sets.nulls if r["env_id"] == env and r["variant"] == variant]
            if not rows:
                missing.append(f"{paper_name(variant)} ({task})")
                continue
            last = max(int(r["step"]) for r in rows)
            rows = sorted((r for r in rows if int(r["step"]) == last), key=lambda r: int(r["seed"]))
            seeds = f"{len(rows)}" + ("" if len(rows) >= COMMAND_SEEDS else f" of {COMMAND_SEEDS} (partial)")
            if env == COMMAND_ENV:
                points = np.array([[float(r["pseudo_command"])] for r in rows])
                per_seed_text = ", ".join(f"{p[0]:.2f}" for p in points)
                mean_text = f"{points.mean():.2f} {unit}"
                for quantity, value in (("pseudo-command mean", points.mean()), ("pseudo-command min", points.min()),
                                        ("pseudo-command max", points.max())):  # fmt: skip
                    record(values_out, env, variant, f"{SECTION} learned null", quantity, value)
            else:
                points = np.array([[float(r["pseudo_goal_x"]), float(r["pseudo_goal_y"])] for r in rows])
                radius = np.linalg.norm(points, axis=1)
                per_seed_text = ", ".join(f"({x:.2f}, {y:.2f})" for x, y in points)
                mean_text = f"{radius.mean():.3f} {unit} from the centre"
                record(values_out, env, variant, f"{SECTION} learned null", "pseudo-goal radius mean", radius.mean())
            edges = sum(r["at_grid_edge"] == "yes" for r in rows)
            kl, own = (np.array([float(r[k]) for r in rows]) for k in ("kl_at_pseudo", "kl_at_own"))
            spread = np.array([float(r["per_state_spread"]) for r in rows])
            for quantity, value in (("KL at pseudo-condition mean", kl.mean()), ("KL to own condition mean", own.mean()),
                                    ("per-state spread mean", spread.mean()), ("seeds", len(rows))):  # fmt: skip
                record(values_out, env, variant, f"{SECTION} learned null", quantity, value)
            table.append(f"| {task} | {name(variant, nulls)} | {seeds} | {per_seed_text}"
                         + (f" ({edges} at the grid's edge)" if edges else "") + f" | {mean_text} | {kl.mean():.2g} | "
                         f"{own.mean():.2f} | {spread.mean():.3f} {unit} |")  # fmt: skip
            readings.append(f"{name(variant, nulls)}, {task}: KL {kl.min():.2g} to {kl.max():.2g} at its closest "
                            f"condition against {own.min():.2f} to {own.max():.2f} to the states' own")  # fmt: skip
    if readings:
        lines += [*table, "", f"Per seed, {'; '.join(readings)}."]
    if missing:
        lines += ["", (f"Not measured yet: {'; '.join(missing)} (`python -m beyond.learned_null <agents> --steps "
                       f"1000000 --output <set>/{LEARNED_NULL}`).")]  # fmt: skip
    return lines


def drawn(sets: Sets) -> tuple[bool, bool]:
    """Whether the figure has a command panel and a goal panel: the dropout set's numbers, and its baselines'."""
    return (any(k[0] == COMMAND_DROPOUT for k in sets.command) and "command baselines" not in sets.absent,
            any(v == GOAL_DROPOUT for v, g in sets.goal) and "goal baselines" not in sets.absent)  # fmt: skip


def figure(sets: Sets, path: Path) -> bool:
    """Tracking error per command band, and Reacher's final distance, against γ for the four variants of each task;
    False (nothing drawn) where neither dropout set has a number."""
    has_command, has_goal = drawn(sets)
    if not has_command and not has_goal:
        return False
    cells = sets.command
    bands = command_bands(sorted({c for (v, s, g, c) in cells}), sets.inside) if has_command else []
    fig, axes = panels(len(bands) + has_goal, 3.4)
    for ax, (band_name, chosen) in zip(axes, bands):
        for variant in (v for v in COMMAND_SET if any(k[0] == v for k in cells)):
            gammas = sorted({g for (v, s, g, c) in cells if v == variant})
            values = [list(per_seed(cells, variant, g, chosen, "error").values()) for g in gammas]
            band(ax, gammas, values, variant, name(variant, COMMAND_SET))
        ax.set_title(f"command task, {band_name} band ({', '.join(f'{c:g}' for c in chosen)} m/s)", fontsize=9)
        ax.set(xlabel="eval guidance γ", ylabel="tracking error (m/s)", xscale="log")
        ticks = sorted({g for (v, s, g, c) in cells})
        ax.set_xticks(ticks, [f"{g:g}" for g in ticks], fontsize=7)
        ax.minorticks_off()
    if has_goal:
        ax = axes[-1]
        for variant in (v for v in GOAL_SET if any(k[0] == v for k in sets.goal)):
            gammas = sorted(g for v, g in sets.goal if v == variant)
            band(ax, gammas, [[d for d, _ in sets.goal[(variant, g)].values()] for g in gammas], variant,
                 name(variant, GOAL_SET))  # fmt: skip
        ax.set_title(f"{GOAL_ENV}: final distance to the goal", fontsize=9)
        ax.set(xlabel="eval guidance γ", ylabel="distance (m, lower is closer)")
    save(fig, axes, path)
    return True
