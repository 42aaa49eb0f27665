"""The text of the section "Guidance on a command": its sentences as templates (filled by text.fill from the tables of
beyond/command.py, which computes every number), its tables' rows, and the verdict, which says what the tests found
and no more."""

from pathlib import Path

import numpy as np

from beyond.command import CommandTables, command_tables, command_values, far_in_table_order, read_tracking, sweep_table
from beyond.sets import COMMAND_ENV, COMMAND_FOLDER, COMMAND_SEEDS
from beyond.text import change_cell, command_name, fill, seeds_cell
from paper_study.agreement import fmt_p, step_label
from paper_study.stats import ALPHA

INTRO = ("HalfCheetah told each episode how fast to run (`paper_study/cheetah_velocity/`: a commanded forward "
         "velocity drawn from the training range, appended to the observation; reward v_cmd − |v − v_cmd| − "
         "0.1·Σa²), trained with the null on the command (`--null-dims 17`: π(a|s, ∅) cannot read the command, but "
         "trained without dropping the command it acts as the policy at one fixed pseudo-command, so γ > 1 pushes "
         "behaviour away from that command rather than amplifying what the command adds: \"What the learned null "
         "is\", in the next section), with the paper's whole-state null, and as PPO, whose "
         "null is never trained (results/beyond/command, `run_all.sh`). Each agent at its last mark is given "
         "commands inside and outside the training range at each eval γ "
         "(`beyond/command_tracking.py`: per episode the mean forward velocity over its 1000 steps; the "
         "tracking error is |achieved − commanded|, the absolute value of tracking.csv's `velocity_error`, not its "
         "`tracking_error`, the reward's mean per-step |v_t − v_cmd|). A velocity command rather than a preference vector over "
         "objectives: a command has a target that an episode misses by a measured amount (how closely it "
         "follows, the analogue of a sample's fidelity to its prompt), a scalar command can be asked outside "
         "its trained range, and it is the meta-RL literature's velocity task, with three differences: there the "
         "velocity is hidden and inferred from reward, the control cost is 0.05·Σa² and some code uses 200-step "
         "episodes; here the command is observed, episodes last 1000 steps and the control cost is gymnasium's "
         "0.1·Σa². A preference has no target of its own, only a point of a Pareto front to be estimated first "
         "(results/beyond/README.md).")  # fmt: skip
NO_FILE = ("**Not run yet:** {folder}/tracking.csv does not exist (results/beyond/command/run_all.sh trains, sweeps and "
           "tracks the set): no numbers here.")  # fmt: skip
NO_EPISODE = "**Not run yet:** {folder}/tracking.csv holds no episode: no numbers here."
PARTIAL = ("**Partial set:** {gaps}. The tables below hold what there is, at {mark}; they are not the set's result, and "
           "a verdict waits for the whole set.")  # fmt: skip
NOTHING = "No γ = 1 cell or no command inside the training range: nothing to compare."
AT_MARK = ("At {mark}: {variants} variants, seeds up to {seeds}, eval γ {gammas:gs}; commands inside the training range "
           "{in_range:gs}, above it {above:gs}, below it {below:gs} (m/s); each seed's value is the mean over its "
           "episodes and the commands named, then mean ± 95% CI over seeds.")  # fmt: skip
TOP = ("At γ = 1 the agents commanded the top of the range ({top:g} m/s) run at {mean:.2f} m/s on average ({low:.2f} to "
       "{high:.2f} over the {agents} agents; {per_variant}): they do not cover the training range, so the tests above "
       "it are made on agents that do not reach its top.")  # fmt: skip
QUESTION_1 = ("**Does γ > 1 make an agent follow its command more closely, and at what cost in return?** The tracking "
              "error and the return over the commands inside the training range at each eval γ, and each γ against "
              "γ = 1: the same seeds and episodes, paired by seed (t test; Holm over the {tests} error tests and apart "
              "over the {tests} return tests; the difference one test detects with 80% power at α = 0.05, before "
              "Holm). A negative error difference follows the command more closely.")  # fmt: skip
QUESTION_2 = ("**Does the command null give a knob that the state null and PPO's untrained null lack?** Each seed's "
              "change in tracking error (inside the training range) from γ = 1 to each γ, the command null's against "
              "each other null's: Welch's t test (distinct runs), Holm over these {tests} tests, the difference one "
              "test detects with 80% power at α = 0.05, before Holm; a negative difference is a larger fall in error "
              "under the command null. Beside it, the gain: the slope of achieved on commanded velocity over those "
              "commands (1 follows every change of command, 0 ignores it), mean ± 95% CI over seeds.")  # fmt: skip
QUESTION_3 = ("**Does guidance extend the range of commands an agent can follow outside the training range?** The "
              "tracking error over the commands above and below the training range at each eval γ, and its change "
              "from γ = 1, paired by seed (t test, Holm over these {tests} tests), and the change one test detects "
              "with 80% power at α = 0.05, before Holm: error (change, p Holm; detectable).")  # fmt: skip
FIGURE = ("Commanded against achieved velocity, one line per eval γ, a panel per variant (mean over seeds, 95% CI band; "
          "the dashed diagonal follows the command exactly, the grey band is the training range):")  # fmt: skip
SWEEP = ("Return at {mark} on commands drawn from the training range (the sweep, episode seeds 10000+), mean ± 95% CI "
         "over seeds, with each variant's seeds counted; and the held-out γ: chosen on that sweep, scored on fresh "
         "episodes (seeds 20000+) against γ = 1 there.")  # fmt: skip
# The verdict, a clause per finding.
FALLS = ("**What these tests say, and no more.** Following more closely: {falls} of the {tests} tests of a γ above 1 "
         "against γ = 1 find a significant fall in tracking error after Holm")  # fmt: skip
LARGEST = ("; the largest fall is {fall:.3f} m/s ({name} at γ {gamma:g}, p {p:p}, Holm {p_holm:p}; one test detects "
           "{detectable:.3f} before Holm)")  # fmt: skip
RISES, RISE = (
    "; {rises} find a significant rise{named}",
    " ({name} at γ {gamma:g}, {difference:+.3f} m/s, Holm p {p_holm:p})",
)
COSTS, COST = ". The cost at γ {top:g}: {costs}", "{name} {difference:+.1f} return (Holm p {p_holm:p})"
KNOB = (". The command null's change against the other nulls' {side} γ = 1: {significant} of {tests} differences "
        "significant after Holm{named}")  # fmt: skip
KNOB_ITEM = "; at γ {gamma:g} against {name} {mean:+.3f} m/s against {baseline_mean:+.3f} (Holm p {p_holm:p})"
GAINS, GAIN = (
    ". The gain (slope of achieved on commanded velocity) from γ = 1 to γ {lowest:g}: {gains}",
    "{name} {at_one:.2f} to {at_lowest:.2f}",
)
OUTSIDE = (". Outside the training range, {significant} of the {tests} tests of a γ against γ = 1 find a significant "
           "change in tracking error after Holm")  # fmt: skip
DETECTS = ("; one test there detects {low:.3f} to {high:.3f} m/s before Holm, so changes of the sizes seen (up to "
           "{largest:+.3f} m/s) can go unfound")  # fmt: skip
CANNOT = (". What they cannot say: a change smaller than one test detects with {seeds} seeds (the detectable columns and "
          "figures, before Holm: after it, more is needed), anything of another task, or of a command of more than one "
          "dimension.")  # fmt: skip


def command_section(folder: Path, values_out: list[dict]) -> list[str]:
    """The command task: does γ set how closely an agent follows its command, and with which null?"""
    lines = ["## Guidance on a command", "", INTRO]
    tracking_csv = folder / COMMAND_FOLDER / "tracking.csv"
    if not tracking_csv.exists():
        return [*lines, "", fill(NO_FILE, folder=COMMAND_FOLDER), ""]
    cells, inside, last = read_tracking(tracking_csv)
    if not cells:
        return [*lines, "", fill(NO_EPISODE, folder=COMMAND_FOLDER), ""]
    t = command_tables(cells, inside, last)
    values_out += command_values(t)
    if t.gaps:
        lines += ["", fill(PARTIAL, gaps="; ".join(t.gaps), mark=step_label(t.last))]
    if not t.comparable:
        return [*lines, "", NOTHING, ""]
    lines += ["", fill(AT_MARK, mark=step_label(t.last), variants=len(t.variants), seeds=t.seeds, gammas=t.gammas,
                       in_range=t.in_range, above=t.above, below=t.below)]  # fmt: skip
    lines += top_of_range_lines(t)
    lines += ["", fill(QUESTION_1, tests=sum(r["error_test"] is not None for r in t.tests)), "",
              "| variant (null) | γ | tracking error (m/s) | vs γ = 1 | p (Holm) | detectable | return | vs γ = 1 | p (Holm) |",
              "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in t.tests:
        error, ret = r["error_test"], r["return_test"]
        error_cells = (
            ["–"] * 3 if error is None else [f"{error['difference']:+.3f}", p_cell(error), f"{error['detectable']:.3f}"]
        )
        return_cells = ["–"] * 2 if ret is None else [f"{ret['difference']:+.1f}", p_cell(ret)]
        lines.append(f"| {command_name(r['variant'])} | {r['gamma']:g} | {seeds_cell(r['error'], 3)} | " + " | ".join(error_cells)
                     + f" | {seeds_cell(r['return'], 1)} | " + " | ".join(return_cells) + " |")  # fmt: skip
    lines += ["", fill(QUESTION_2, tests=len(t.knob)), "",
              "| γ | baseline | command null's change | baseline's change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    lines += [f"| {r['gamma']:g} | {command_name(r['baseline'])} | {r['mean']:+.3f} | {r['baseline_mean']:+.3f} | "
              f"{r['mean'] - r['baseline_mean']:+.3f} | {p_cell(r)} | {r['detectable']:.3f} |" for r in t.knob]  # fmt: skip
    lines += ["", "| variant (null) | " + " | ".join(f"gain at γ = {g:g}" for g in t.gammas) + " |",
              "|---|" + "---|" * len(t.gammas)]  # fmt: skip
    lines += [
        f"| {command_name(v)} | " + " | ".join(seeds_cell(g) for g in t.gains[v].values()) + " |" for v in t.variants
    ]
    if t.outside:
        lines += ["", fill(QUESTION_3, tests=sum(r["test"] is not None for r in t.far)), "",
                  "| variant (null) | commands | " + " | ".join(f"γ = {g:g}" for g in t.gammas) + " |",
                  "|---|---|" + "---|" * len(t.gammas)]  # fmt: skip
        rows = far_in_table_order(t)
        for variant in t.variants:
            for side, chosen in t.outside:
                shown = [
                    change_cell(r["error"], r["test"], 3) for r in rows if r["variant"] == variant and r["side"] == side
                ]
                lines.append(f"| {command_name(variant)} | {side} ({', '.join(f'{c:g}' for c in chosen)}) | "
                             + " | ".join(shown) + " |")  # fmt: skip
    lines += command_verdict(t)
    lines += [
        "",
        FIGURE,
        "",
        f"![Commanded against achieved velocity, one line per eval γ]({COMMAND_FOLDER}/command_tracking.png)",
    ]
    lines += command_sweep_lines(folder / COMMAND_FOLDER, COMMAND_ENV)
    return [*lines, ""]


def p_cell(test: dict) -> str:
    return f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})"


def top_of_range_lines(t: CommandTables) -> list[str]:
    """How fast the agents run at γ = 1 when commanded the top of the training range: whether they cover it, which
    the tests outside the range presume."""
    every = [speed for v in t.variants for speed in t.speeds[v].values()]
    if not every:
        return []
    means = {v: float(np.mean(list(seeds.values()))) for v, seeds in t.speeds.items() if seeds}
    per_variant = "; ".join(f"{command_name(v)} {m:.2f}" for v, m in means.items())
    return ["", fill(TOP, top=t.top, mean=np.mean(every), low=min(every), high=max(every), agents=len(every),
                     per_variant=per_variant)]  # fmt: skip


def command_verdict(t: CommandTables) -> list[str]:
    """What the command section's tests say, from their results alone: the falls in tracking error that γ > 1
    gives, its cost in return at the largest γ, where the command null's change differs from the other nulls'
    (below and above γ = 1), and the tests outside the training range; none for a partial set."""
    if t.gaps:
        return []
    above_one = [r for r in t.tests if r["gamma"] > 1 and r["error_test"] is not None]
    found = lambda sign: [
        r for r in above_one if sign * r["error_test"]["difference"] > 0 and r["error_test"]["p_holm"] < ALPHA
    ]
    falls, rises = found(-1), found(+1)
    best = min(above_one, key=lambda r: r["error_test"]["difference"], default=None)
    top = max((r["gamma"] for r in above_one), default=None)
    costs = [r for r in t.tests if r["gamma"] == top and r["return_test"] is not None]
    parts = [fill(FALLS, falls=len(falls), tests=len(above_one))]
    if best is not None and best["error_test"]["difference"] < 0:
        test = best["error_test"]
        parts.append(fill(LARGEST, fall=-test["difference"], name=command_name(best["variant"]), gamma=best["gamma"],
                          p=test["p"], p_holm=test["p_holm"], detectable=test["detectable"]))  # fmt: skip
    named = "".join(fill(RISE, name=command_name(r["variant"]), gamma=r["gamma"], **r["error_test"]) for r in rises)
    parts.append(fill(RISES, rises=len(rises), named=named))
    if costs:
        parts.append(fill(COSTS, top=top, costs="; ".join(fill(COST, name=command_name(r["variant"]), **r["return_test"])
                                                           for r in costs)))  # fmt: skip
    for side, rows in (
        ("below", [r for r in t.knob if r["gamma"] < 1]),
        ("above", [r for r in t.knob if r["gamma"] > 1]),
    ):
        differing = [r for r in rows if r["p_holm"] < ALPHA]
        named = "".join(fill(KNOB_ITEM, **{**r, "name": command_name(r["baseline"])}) for r in differing)
        parts.append(fill(KNOB, side=side, significant=len(differing), tests=len(rows), named=named))
    lowest = min((g for v in t.gains for g in t.gains[v]), default=None)
    if lowest is not None and lowest < 1:
        gains = [(v, t.gains[v]) for v in t.gains if t.gains[v].get(1.0) and t.gains[v].get(lowest)]
        parts.append(fill(GAINS, lowest=lowest, gains="; ".join(
            fill(GAIN, name=command_name(v), at_one=np.mean(list(g[1.0].values())), at_lowest=np.mean(list(g[lowest].values())))
            for v, g in gains)))  # fmt: skip
    outside = [r["test"] for r in t.far if r["test"] is not None]
    parts.append(fill(OUTSIDE, significant=sum(r["p_holm"] < ALPHA for r in outside), tests=len(outside)))
    if outside:
        detectable = [r["detectable"] for r in outside]
        parts.append(
            fill(DETECTS, low=min(detectable), high=max(detectable), largest=max(r["difference"] for r in outside))
        )
    parts.append(fill(CANNOT, seeds=COMMAND_SEEDS))
    return ["", "".join(parts)]


def command_sweep_lines(base: Path, env: str) -> list[str]:
    """The set's sweep on the training distribution of commands (episodes.csv) and its held-out γ, where they exist."""
    table = sweep_table(base, env)
    if table is None:
        return ["", f"The set's return sweep ({COMMAND_FOLDER}/episodes.csv) is not there yet."]
    if not table["rows"]:
        return ["", f"{COMMAND_FOLDER}/episodes.csv holds no episode of the command task's variants."]
    gammas = table["gammas"]
    lines = ["", fill(SWEEP, mark=step_label(table["last"])), "",
             "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " | held-out γ: fresh gain |",
             "|---|---|" + "---|" * (len(gammas) + 1)]  # fmt: skip
    for row in table["rows"]:
        shown = [seeds_cell(row["cells"][g], 1) if g in row["cells"] else "–" for g in gammas]
        lines.append(
            f"| {command_name(row['variant'])} | {row['seeds']} | "
            + " | ".join(shown)
            + f" | {held_cell(row['held'])} |"
        )
    return lines


def held_cell(held: dict | None) -> str:
    """A heldout_gamma.csv row as the sweep's table shows it: the chosen γ and its fresh gain, or why none."""
    if held and held["status"] == "tested":
        return (f"{float(held['selected_gamma']):g}: {float(held['fresh_gain']):+.1f} ± {float(held['fresh_gain_ci95']):.1f} "
                f"(p {fmt_p(float(held['p']))}, Holm {fmt_p(float(held['p_holm']))})")  # fmt: skip
    return f"{float(held['selected_gamma']):g}: {held['status']}" if held else "–"
