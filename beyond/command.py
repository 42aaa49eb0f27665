"""The section "Guidance on a command": does γ set how closely an agent follows its command, and with which
null? From results/beyond/command/tracking.csv (beyond/command_tracking.py) and the set's sweep."""

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from beyond.cells import cells_of, last_step, read_rows, record, seed_means
from beyond.sets import COMMAND_ENV, COMMAND_FOLDER, COMMAND_NULL, COMMAND_SEEDS, COMMAND_VARIANTS
from beyond.text import command_name, seeds_cell
from paper_study.agreement import fmt_p, step_label
from paper_study.paper import paper_name
from paper_study.stats import ALPHA, holm, paired_test, welch_of
from pgg_utils.files import read_csv


def read_tracking(path: Path, variants=None) -> tuple[dict, dict, int]:
    """({(variant, seed, γ, command): {"error": mean |achieved − commanded| velocity, "step_error": mean of the
    reward's per-step error (`tracking_error`), "velocity": mean achieved velocity, "return": mean return,
    "episodes": n}} over the episodes of tracking.csv at its last step, {command: inside the training range}, that
    step); of `variants` alone where given (the step is then theirs)."""
    rows = [r for r in read_csv(path) if variants is None or r["variant"] in variants]
    if not rows:
        return {}, {}, 0
    last = max(int(r["step"]) for r in rows)
    episodes = defaultdict(list)
    for r in rows:
        if int(r["step"]) == last:
            episodes[(r["variant"], int(r["seed"]), float(r["eval_guidance"]), float(r["command"]))].append(
                (abs(float(r["velocity_error"])), float(r["tracking_error"]), float(r["mean_velocity"]),
                 float(r["return"]))
            )  # fmt: skip
    inside = {float(r["command"]): r["in_training_range"] == "yes" for r in rows}
    cells = {}
    for key, values in episodes.items():
        means = np.mean(values, axis=0)
        cells[key] = {"error": means[0], "step_error": means[1], "velocity": means[2], "return": means[3],
                      "episodes": len(values)}  # fmt: skip
    return cells, inside, last


def tracking_gaps(cells: dict) -> list[str]:
    """What the set lacks to be whole: COMMAND_SEEDS seeds of every variant, each at every (γ, command) that any
    seed has, with as many episodes as the fullest cell; [] where it is whole."""
    grid = {(g, c) for (v, s, g, c) in cells}
    episodes = max((cell["episodes"] for cell in cells.values()), default=0)
    gaps = []
    for variant in COMMAND_VARIANTS:
        seeds = sorted({s for (v, s, g, c) in cells if v == variant})
        if len(seeds) < COMMAND_SEEDS:
            gaps.append(f"{paper_name(variant)}: {len(seeds)} of {COMMAND_SEEDS} seeds")
        short = sorted(f"seed {s}" for s in seeds for g, c in grid
                       if cells.get((variant, s, g, c), {"episodes": 0})["episodes"] < episodes)  # fmt: skip
        if short:
            gaps.append(
                f"{paper_name(variant)}: cells missing or short of {episodes} episodes ({', '.join(sorted(set(short)))})"
            )
    return gaps


def per_seed(cells: dict, variant: str, gamma: float, commands: list[float], quantity: str) -> dict:
    """{seed: the mean over `commands` of a cell field} for the seeds that hold every one of those cells."""
    seeds = sorted({s for (v, s, g, c) in cells if v == variant})
    return {s: float(np.mean([cells[(variant, s, gamma, c)][quantity] for c in commands])) for s in seeds
            if all((variant, s, gamma, c) in cells for c in commands)}  # fmt: skip


def change_of(at: dict, reference: dict) -> dict:
    return {seed: at[seed] - reference[seed] for seed in at if seed in reference}


def gain(cells: dict, variant: str, gamma: float, commands: list[float]) -> dict:
    """{seed: the slope of achieved on commanded velocity over `commands`}: 1 follows every change of command."""
    out = {}
    for seed in sorted({s for (v, s, g, c) in cells if v == variant}):
        if all((variant, seed, gamma, c) in cells for c in commands) and len(commands) > 1:
            out[seed] = float(
                np.polyfit(commands, [cells[(variant, seed, gamma, c)]["velocity"] for c in commands], 1)[0]
            )
    return out


def command_section(folder: Path, values_out: list[dict]) -> list[str]:
    """The command task: does γ set how closely an agent follows its command, and with which null?"""
    base = folder / COMMAND_FOLDER
    lines = ["## Guidance on a command", "",
             ("HalfCheetah told each episode how fast to run (`paper_study/cheetah_velocity/`: a commanded forward "
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
              "(results/beyond/README.md).")]  # fmt: skip
    tracking_csv = base / "tracking.csv"
    if not tracking_csv.exists():
        return [*lines, "", (f"**Not run yet:** {COMMAND_FOLDER}/tracking.csv does not exist (results/beyond/command/run_all.sh "
                             "trains, sweeps and tracks the set): no numbers here."), ""]  # fmt: skip
    cells, inside, last = read_tracking(tracking_csv)
    if not cells:
        return [*lines, "", f"**Not run yet:** {COMMAND_FOLDER}/tracking.csv holds no episode: no numbers here.", ""]
    env = COMMAND_ENV
    gammas = sorted({g for (v, s, g, c) in cells})
    commands = sorted({c for (v, s, g, c) in cells})
    in_range = [c for c in commands if inside[c]]
    low, high = (min(in_range), max(in_range)) if in_range else (math.nan, math.nan)
    above, below = (
        [c for c in commands if not inside[c] and c > high],
        [c for c in commands if not inside[c] and c < low],
    )
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == v for k in cells)]
    gaps = tracking_gaps(cells)
    record(values_out, env, "", "command", "whole", float(not gaps))
    if gaps:
        lines += ["", (f"**Partial set:** {'; '.join(gaps)}. The tables below hold what there is, at {step_label(last)}; "
                       "they are not the set's result, and a verdict waits for the whole set.")]  # fmt: skip
    if 1.0 not in gammas or not in_range:
        return [*lines, "", "No γ = 1 cell or no command inside the training range: nothing to compare.", ""]
    seeds = len({s for (v, s, g, c) in cells})
    lines += ["", (f"At {step_label(last)}: {len(variants)} variants, seeds up to {seeds}, eval γ "
                   f"{', '.join(f'{g:g}' for g in gammas)}; commands inside the training range "
                   f"{', '.join(f'{c:g}' for c in in_range)}, above it {', '.join(f'{c:g}' for c in above) or 'none'}, "
                   f"below it {', '.join(f'{c:g}' for c in below) or 'none'} (m/s); each seed's value is the mean over "
                   "its episodes and the commands named, then mean ± 95% CI over seeds.")]  # fmt: skip
    lines += top_of_range_lines(cells, variants, high, env, values_out)

    # Question 1: tracking error and return against γ, each γ against γ = 1 on the same seeds and episodes.
    tests = []
    for variant in variants:
        reference_error = per_seed(cells, variant, 1.0, in_range, "error")
        reference_return = per_seed(cells, variant, 1.0, in_range, "return")
        for gamma in gammas:
            error, ret = (
                per_seed(cells, variant, gamma, in_range, "error"),
                per_seed(cells, variant, gamma, in_range, "return"),
            )
            tests.append({"variant": variant, "gamma": gamma, "error": error, "return": ret,
                          "error_test": None if gamma == 1.0 else paired_test(error, reference_error),
                          "return_test": None if gamma == 1.0 else paired_test(ret, reference_return)})  # fmt: skip
    for kind in ("error_test", "return_test"):
        tested = [t[kind] for t in tests if t[kind] is not None]
        for test, p_holm in zip(tested, holm([t["p"] for t in tested])):
            test["p_holm"] = p_holm
    family = sum(t["error_test"] is not None for t in tests)
    lines += ["", ("**Does γ > 1 make an agent follow its command more closely, and at what cost in return?** The "
                   "tracking error and the return over the commands inside the training range at each eval γ, and "
                   "each γ against γ = 1: the same seeds and episodes, paired by seed (t test; Holm over the "
                   f"{family} error tests and apart over the {family} return tests; the difference one test detects "
                   "with 80% power at α = 0.05, before Holm). A negative error difference follows the command more "
                   "closely."), "",
              ("| variant (null) | γ | tracking error (m/s) | vs γ = 1 | p (Holm) | detectable | return | vs γ = 1 | "
               "p (Holm) |"), "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for t in tests:
        name = command_name(t["variant"])
        error_cells, return_cells = ["–", "–", "–"], ["–", "–"]
        if t["error"]:
            record(
                values_out,
                env,
                t["variant"],
                "",
                f"tracking error at γ {t['gamma']:g}",
                np.mean(list(t["error"].values())),
            )
            record(
                values_out, env, t["variant"], "", f"return at γ {t['gamma']:g}", np.mean(list(t["return"].values()))
            )
        if (test := t["error_test"]) is not None:
            error_cells = [f"{test['difference']:+.3f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})",
                           f"{test['detectable']:.3f}"]  # fmt: skip
            for quantity, value in (("tracking error change", test["difference"]), ("tracking error p", test["p"]),
                                    ("tracking error p Holm", test["p_holm"]),
                                    ("tracking error detectable", test["detectable"])):  # fmt: skip
                record(values_out, env, t["variant"], "γ 1", f"{quantity} at γ {t['gamma']:g}", value)
        if (test := t["return_test"]) is not None:
            return_cells = [f"{test['difference']:+.1f}", f"{fmt_p(test['p'])} ({fmt_p(test['p_holm'])})"]
            for quantity, value in (("return change", test["difference"]), ("return p", test["p"]),
                                    ("return p Holm", test["p_holm"])):  # fmt: skip
                record(values_out, env, t["variant"], "γ 1", f"{quantity} at γ {t['gamma']:g}", value)
        lines.append(f"| {name} | {t['gamma']:g} | {seeds_cell(t['error'], 3)} | " + " | ".join(error_cells)
                     + f" | {seeds_cell(t['return'], 1)} | " + " | ".join(return_cells) + " |")  # fmt: skip

    # Question 2: the command null's change in error from γ = 1 against the other nulls' (distinct runs: Welch).
    knob = []
    reference = {v: per_seed(cells, v, 1.0, in_range, "error") for v in variants}
    for gamma in (g for g in gammas if g != 1.0):
        ours = change_of(per_seed(cells, COMMAND_NULL, gamma, in_range, "error"), reference.get(COMMAND_NULL, {}))
        for baseline in (v for v in variants if v != COMMAND_NULL):
            theirs = change_of(per_seed(cells, baseline, gamma, in_range, "error"), reference[baseline])
            if len(ours) >= 2 and len(theirs) >= 2:
                knob.append(
                    {"gamma": gamma, "baseline": baseline, **welch_of(list(ours.values()), list(theirs.values()))}
                )
    for row, p_holm in zip(knob, holm([r["p"] for r in knob])):
        row["p_holm"] = p_holm
    lines += ["", ("**Does the command null give a knob that the state null and PPO's untrained null lack?** Each "
                   "seed's change in tracking error (inside the training range) from γ = 1 to each γ, the command "
                   "null's against each other null's: Welch's t test (distinct runs), Holm over these "
                   f"{len(knob)} tests, the difference one test detects with 80% power at α = 0.05, before Holm; a "
                   "negative difference is a larger fall in error under the command null. Beside it, the gain: the "
                   "slope of achieved on commanded velocity over those commands (1 follows every change of command, "
                   "0 ignores it), mean ± 95% CI over seeds."), "",
              "| γ | baseline | command null's change | baseline's change | difference | p (Holm) | detectable |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in knob:
        for quantity, value in (("knob change", r["mean"]), ("baseline's knob change", r["baseline_mean"]),
                                ("knob difference", r["mean"] - r["baseline_mean"]), ("knob p", r["p"]),
                                ("knob p Holm", r["p_holm"]), ("knob detectable", r["detectable"])):  # fmt: skip
            record(values_out, env, COMMAND_NULL, r["baseline"], f"{quantity} at γ {r['gamma']:g}", value)
        lines.append(f"| {r['gamma']:g} | {command_name(r['baseline'])} | "
                     f"{r['mean']:+.3f} | {r['baseline_mean']:+.3f} | {r['mean'] - r['baseline_mean']:+.3f} | "
                     f"{fmt_p(r['p'])} ({fmt_p(r['p_holm'])}) | {r['detectable']:.3f} |")  # fmt: skip
    lines += ["", "| variant (null) | " + " | ".join(f"gain at γ = {g:g}" for g in gammas) + " |",
              "|---|" + "---|" * len(gammas)]  # fmt: skip
    gains = {v: {g: gain(cells, v, g, in_range) for g in gammas} for v in variants}
    for variant in variants:
        for gamma, by_seed in gains[variant].items():
            if by_seed:
                record(values_out, env, variant, "", f"gain at γ {gamma:g}", np.mean(list(by_seed.values())))
        lines.append(f"| {command_name(variant)} | "
                     + " | ".join(seeds_cell(g) for g in gains[variant].values()) + " |")  # fmt: skip

    # Question 3: outside the training range, each γ against γ = 1, paired by seed.
    outside = [(side, chosen) for side, chosen in (("above", above), ("below", below)) if chosen]
    far = []
    for variant in variants:
        for side, chosen in outside:
            reference_error = per_seed(cells, variant, 1.0, chosen, "error")
            for gamma in gammas:
                error = per_seed(cells, variant, gamma, chosen, "error")
                far.append({"variant": variant, "side": side, "gamma": gamma, "error": error,
                            "test": None if gamma == 1.0 else paired_test(error, reference_error)})  # fmt: skip
    tested = [r["test"] for r in far if r["test"] is not None]
    for test, p_holm in zip(tested, holm([t["p"] for t in tested])):
        test["p_holm"] = p_holm
    if outside:
        lines += ["", ("**Does guidance extend the range of commands an agent can follow outside the training range?** "
                       "The tracking error over the commands above and below the training range at each eval γ, and "
                       "its change from γ = 1, paired by seed (t test, Holm over these "
                       f"{len(tested)} tests), and the change one test detects with 80% power at α = 0.05, before "
                       "Holm: error (change, p Holm; detectable)."), "",
                  "| variant (null) | commands | " + " | ".join(f"γ = {g:g}" for g in gammas) + " |",
                  "|---|---|" + "---|" * len(gammas)]  # fmt: skip
        for variant in variants:
            for side, chosen in outside:
                row = [r for r in far if r["variant"] == variant and r["side"] == side]
                shown = []
                for r in row:
                    if not r["error"]:
                        shown.append("–")
                        continue
                    mean = float(np.mean(list(r["error"].values())))
                    record(values_out, env, variant, "", f"tracking error {side} the range at γ {r['gamma']:g}", mean)
                    if r["test"] is None:
                        shown.append(f"{mean:.3f}")
                        continue
                    for quantity, value in (("change", r["test"]["difference"]), ("p", r["test"]["p"]),
                                            ("p Holm", r["test"]["p_holm"]), ("detectable", r["test"]["detectable"])):  # fmt: skip
                        record(values_out, env, variant, "γ 1", f"tracking error {side} the range {quantity} at "
                               f"γ {r['gamma']:g}", value)  # fmt: skip
                    shown.append(f"{mean:.3f} ({r['test']['difference']:+.3f}, {fmt_p(r['test']['p_holm'])}; "
                                 f"{r['test']['detectable']:.3f})")  # fmt: skip
                lines.append(f"| {command_name(variant)} | {side} "
                             f"({', '.join(f'{c:g}' for c in chosen)}) | " + " | ".join(shown) + " |")  # fmt: skip
    lines += command_verdict(tests, knob, tested, gains, gaps)
    lines += ["", ("Commanded against achieved velocity, one line per eval γ, a panel per variant (mean over seeds, "
                   "95% CI band; the dashed diagonal follows the command exactly, the grey band is the training "
                   "range):"), "",
              f"![Commanded against achieved velocity, one line per eval γ]({COMMAND_FOLDER}/command_tracking.png)"]  # fmt: skip
    lines += command_sweep_lines(base, env)
    return [*lines, ""]


def top_of_range_lines(cells: dict, variants: list[str], top: float, env: str, values_out: list[dict]) -> list[str]:
    """How fast the agents run at γ = 1 when commanded the top of the training range: whether they cover it, which
    the tests outside the range presume."""
    speeds = {v: per_seed(cells, v, 1.0, [top], "velocity") for v in variants}
    every = [speed for v in variants for speed in speeds[v].values()]
    if not every:
        return []
    means = {v: float(np.mean(list(seeds.values()))) for v, seeds in speeds.items() if seeds}
    for variant, baseline, value in (("", "command", np.mean(every)), *((v, "", m) for v, m in means.items())):
        record(values_out, env, variant, baseline, f"velocity at command {top:g} at γ 1", value)
    return ["", (f"At γ = 1 the agents commanded the top of the range ({top:g} m/s) run at {np.mean(every):.2f} m/s on "
                 f"average ({min(every):.2f} to {max(every):.2f} over the {len(every)} agents; "
                 + "; ".join(f"{command_name(v)} {m:.2f}" for v, m in means.items())
                 + "): they do not cover the training range, so the tests above it are made on agents that do not "
                 "reach its top.")]  # fmt: skip


def command_verdict(
    tests: list[dict], knob: list[dict], outside: list[dict], gains: dict, gaps: list[str]
) -> list[str]:
    """What the command section's tests say, from their results alone: the falls in tracking error that γ > 1
    gives, its cost in return at the largest γ, where the command null's change differs from the other
    nulls' (below and above γ = 1), and the tests outside the training range; none for a partial set."""
    if gaps:
        return []
    above_one = [t for t in tests if t["gamma"] > 1 and t["error_test"] is not None]
    found = lambda sign: [
        t for t in above_one if sign * t["error_test"]["difference"] > 0 and t["error_test"]["p_holm"] < ALPHA
    ]
    falls, rises = found(-1), found(+1)
    best = min(above_one, key=lambda t: t["error_test"]["difference"], default=None)
    top = max((t["gamma"] for t in above_one), default=None)
    costs = [t for t in tests if t["gamma"] == top and t["return_test"] is not None]
    parts = [(f"**What these tests say, and no more.** Following more closely: {len(falls)} of the {len(above_one)} "
              "tests of a γ above 1 against γ = 1 find a significant fall in tracking error after Holm")]  # fmt: skip
    if best is not None and best["error_test"]["difference"] < 0:
        test = best["error_test"]
        parts.append(f"; the largest fall is {-test['difference']:.3f} m/s ({command_name(best['variant'])} at γ {best['gamma']:g}, "
                     f"p {fmt_p(test['p'])}, Holm {fmt_p(test['p_holm'])}; one test detects {test['detectable']:.3f} before Holm)")  # fmt: skip
    parts.append(f"; {len(rises)} find a significant rise" + "".join(
        f" ({command_name(t['variant'])} at γ {t['gamma']:g}, {t['error_test']['difference']:+.3f} m/s, Holm p "
        f"{fmt_p(t['error_test']['p_holm'])})" for t in rises))  # fmt: skip
    if costs:
        parts.append(f". The cost at γ {top:g}: " + "; ".join(
            f"{command_name(t['variant'])} {t['return_test']['difference']:+.1f} return (Holm p {fmt_p(t['return_test']['p_holm'])})"
            for t in costs))  # fmt: skip
    for side, rows in (("below", [r for r in knob if r["gamma"] < 1]), ("above", [r for r in knob if r["gamma"] > 1])):
        differing = [r for r in rows if r["p_holm"] < ALPHA]
        parts.append(f". The command null's change against the other nulls' {side} γ = 1: {len(differing)} of {len(rows)} "
                     "differences significant after Holm" + "".join(
                         f"; at γ {r['gamma']:g} against {command_name(r['baseline'])} {r['mean']:+.3f} m/s against "
                         f"{r['baseline_mean']:+.3f} (Holm p {fmt_p(r['p_holm'])})" for r in differing))  # fmt: skip
    lowest = min((g for v in gains for g in gains[v]), default=None)
    if lowest is not None and lowest < 1:
        parts.append(f". The gain (slope of achieved on commanded velocity) from γ = 1 to γ {lowest:g}: " + "; ".join(
            f"{command_name(v)} {np.mean(list(gains[v][1.0].values())):.2f} to {np.mean(list(gains[v][lowest].values())):.2f}"
            for v in gains if gains[v].get(1.0) and gains[v].get(lowest)))  # fmt: skip
    significant = [r for r in outside if r["p_holm"] < ALPHA]
    parts.append(f". Outside the training range, {len(significant)} of the {len(outside)} tests of a γ against γ = 1 "
                 "find a significant change in tracking error after Holm")  # fmt: skip
    if outside:
        detectable = [t["detectable"] for t in outside]
        parts.append(f"; one test there detects {min(detectable):.3f} to {max(detectable):.3f} m/s before "
                     "Holm, so changes of the sizes seen (up to "
                     f"{max(t['difference'] for t in outside):+.3f} m/s) can go unfound")  # fmt: skip
    parts.append(f". What they cannot say: a change smaller than one test detects with {COMMAND_SEEDS} seeds (the "
                 "detectable columns and figures, before Holm: after it, more is needed), anything of another task, or "
                 "of a command of more than one dimension.")  # fmt: skip
    return ["", "".join(parts)]


def command_sweep_lines(base: Path, env: str) -> list[str]:
    """The set's sweep on the training distribution of commands (episodes.csv) and its held-out γ, where they exist."""
    if not (base / "episodes.csv").exists():
        return ["", f"The set's return sweep ({COMMAND_FOLDER}/episodes.csv) is not there yet."]
    means = seed_means(read_rows(base / "episodes.csv"))
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == env and k[1] == v for k in means)]
    if not variants:
        return ["", f"{COMMAND_FOLDER}/episodes.csv holds no episode of the command task's variants."]
    last = last_step(means, env)
    gammas = sorted({g for (e, v, s, g) in means if e == env and s == last})
    lines = ["", (f"Return at {step_label(last)} on commands drawn from the training range (the sweep, episode seeds "
                  "10000+), mean ± 95% CI over seeds, with each variant's seeds counted; and the held-out γ: chosen "
                  "on that sweep, scored on fresh episodes (seeds 20000+) against γ = 1 there."), "",
             "| variant (null) | seeds | " + " | ".join(f"γ = {g:g}" for g in gammas) + " | held-out γ: fresh gain |",
             "|---|---|" + "---|" * (len(gammas) + 1)]  # fmt: skip
    heldout = {}
    if (base / "heldout_gamma.csv").exists():
        heldout = {
            (r["variant"], int(r["step"])): r for r in read_csv(base / "heldout_gamma.csv") if r["env_id"] == env
        }
    for variant in variants:
        cells = cells_of(means, env, variant)
        shown = [seeds_cell(cells[(last, g)], 1) if (last, g) in cells else "–" for g in gammas]
        seeds = max((len(cells[(last, g)]) for g in gammas if (last, g) in cells), default=0)
        held = heldout.get((variant, last))
        chosen = "–"
        if held and held["status"] == "tested":
            chosen = (f"{float(held['selected_gamma']):g}: {float(held['fresh_gain']):+.1f} ± "
                      f"{float(held['fresh_gain_ci95']):.1f} (p {fmt_p(float(held['p']))}, Holm "
                      f"{fmt_p(float(held['p_holm']))})")  # fmt: skip
        elif held:
            chosen = f"{float(held['selected_gamma']):g}: {held['status']}"
        lines.append(f"| {command_name(variant)} | {seeds} | " + " | ".join(shown)
                     + f" | {chosen} |")  # fmt: skip
    return lines
