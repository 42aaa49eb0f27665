"""The numbers of the section "Guidance on a command" (its text: beyond/command_text.py): does γ set how closely an
agent follows its command, and with which null? From results/beyond/command/tracking.csv (beyond/command_tracking.py)
and the set's sweep: the tracking cells, what the set lacks to be whole, the tests of each question as tables
(CommandTables), the rows they give report_values.csv (command_values), and the sweep's table (sweep_table)."""

import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from beyond.cells import cells_of, last_step, read_rows, record, seed_means
from beyond.sets import COMMAND_ENV, COMMAND_NULL, COMMAND_SEEDS, COMMAND_VARIANTS
from paper_study.paper import paper_name
from paper_study.stats import paired_test, set_holm, welch_of
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


@dataclass
class CommandTables:
    """The command set at its last step (`last`) and every table the section shows: the commands inside the training
    range and outside it; `gaps`, what the set lacks to be whole; `speeds`, each variant's {seed: velocity} at γ = 1
    commanded the top of the range (`top`); `tests`, each variant's tracking error and return over the range at each γ,
    tested against γ = 1 (question 1); `knob`, the command null's change from γ = 1 against each other null's (question
    2); `gains`, {variant: {γ: {seed: gain}}}; `far`, the tracking error outside the range, tested against γ = 1
    (question 3). The tests are empty where no γ = 1 cell or no command inside the range leaves anything to compare."""

    env: str
    last: int
    gammas: list
    in_range: list
    above: list
    below: list
    variants: list
    gaps: list
    seeds: int
    comparable: bool
    top: float = math.nan
    speeds: dict = field(default_factory=dict)
    tests: list = field(default_factory=list)
    knob: list = field(default_factory=list)
    gains: dict = field(default_factory=dict)
    outside: list = field(default_factory=list)
    far: list = field(default_factory=list)


def command_tables(cells: dict, inside: dict, last: int) -> CommandTables:
    """Every test of the section, each family under Holm once."""
    gammas, commands = sorted({g for (v, s, g, c) in cells}), sorted({c for (v, s, g, c) in cells})
    in_range = [c for c in commands if inside[c]]
    low, high = (min(in_range), max(in_range)) if in_range else (math.nan, math.nan)
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == v for k in cells)]
    t = CommandTables(env=COMMAND_ENV, last=last, gammas=gammas, in_range=in_range,
                      above=[c for c in commands if not inside[c] and c > high],
                      below=[c for c in commands if not inside[c] and c < low], variants=variants,
                      gaps=tracking_gaps(cells), seeds=len({s for (v, s, g, c) in cells}),
                      comparable=1.0 in gammas and bool(in_range), top=high)  # fmt: skip
    if not t.comparable:
        return t
    t.speeds = {v: per_seed(cells, v, 1.0, [high], "velocity") for v in variants}
    # Question 1: tracking error and return against γ, each γ against γ = 1 on the same seeds and episodes.
    for variant in variants:
        reference = {q: per_seed(cells, variant, 1.0, in_range, q) for q in ("error", "return")}
        for gamma in gammas:
            error, ret = (
                per_seed(cells, variant, gamma, in_range, "error"),
                per_seed(cells, variant, gamma, in_range, "return"),
            )
            t.tests.append({"variant": variant, "gamma": gamma, "error": error, "return": ret,
                            "error_test": None if gamma == 1.0 else paired_test(error, reference["error"]),
                            "return_test": None if gamma == 1.0 else paired_test(ret, reference["return"])})  # fmt: skip
    for kind in ("error_test", "return_test"):
        set_holm([r[kind] for r in t.tests])
    # Question 2: the command null's change in error from γ = 1 against the other nulls' (distinct runs: Welch).
    reference = {v: per_seed(cells, v, 1.0, in_range, "error") for v in variants}
    for gamma in (g for g in gammas if g != 1.0):
        ours = change_of(per_seed(cells, COMMAND_NULL, gamma, in_range, "error"), reference.get(COMMAND_NULL, {}))
        for baseline in (v for v in variants if v != COMMAND_NULL):
            theirs = change_of(per_seed(cells, baseline, gamma, in_range, "error"), reference[baseline])
            if len(ours) >= 2 and len(theirs) >= 2:
                t.knob.append(
                    {"gamma": gamma, "baseline": baseline, **welch_of(list(ours.values()), list(theirs.values()))}
                )
    set_holm(t.knob)
    t.gains = {v: {g: gain(cells, v, g, in_range) for g in gammas} for v in variants}
    # Question 3: outside the training range, each γ against γ = 1, paired by seed.
    t.outside = [(side, chosen) for side, chosen in (("above", t.above), ("below", t.below)) if chosen]
    for variant in variants:
        for side, chosen in t.outside:
            reference_error = per_seed(cells, variant, 1.0, chosen, "error")
            for gamma in gammas:
                error = per_seed(cells, variant, gamma, chosen, "error")
                t.far.append({"variant": variant, "side": side, "gamma": gamma, "error": error,
                              "test": None if gamma == 1.0 else paired_test(error, reference_error)})  # fmt: skip
    set_holm([r["test"] for r in t.far])
    return t


def command_values(t: CommandTables) -> list[dict]:
    """The section's rows of report_values.csv, from its tables, in the order the section shows them."""
    out, env, mean = [], t.env, lambda seeds: np.mean(list(seeds.values()))
    record(out, env, "", "command", "whole", float(not t.gaps))
    if every := [speed for v in t.variants for speed in t.speeds.get(v, {}).values()]:
        record(out, env, "", "command", f"velocity at command {t.top:g} at γ 1", np.mean(every))
        for variant in (v for v in t.variants if t.speeds[v]):
            record(out, env, variant, "", f"velocity at command {t.top:g} at γ 1", mean(t.speeds[variant]))
    quantities = {"error_test": (("tracking error change", "difference"), ("tracking error p", "p"),
                                 ("tracking error p Holm", "p_holm"), ("tracking error detectable", "detectable")),
                  "return_test": (("return change", "difference"), ("return p", "p"), ("return p Holm", "p_holm"))}  # fmt: skip
    for r in t.tests:
        if r["error"]:
            record(out, env, r["variant"], "", f"tracking error at γ {r['gamma']:g}", mean(r["error"]))
            record(out, env, r["variant"], "", f"return at γ {r['gamma']:g}", mean(r["return"]))
        for kind, named in quantities.items():
            if (test := r[kind]) is not None:
                for quantity, key in named:
                    record(out, env, r["variant"], "γ 1", f"{quantity} at γ {r['gamma']:g}", test[key])
    for r in t.knob:
        for quantity, value in (("knob change", r["mean"]), ("baseline's knob change", r["baseline_mean"]),
                                ("knob difference", r["mean"] - r["baseline_mean"]), ("knob p", r["p"]),
                                ("knob p Holm", r["p_holm"]), ("knob detectable", r["detectable"])):  # fmt: skip
            record(out, env, COMMAND_NULL, r["baseline"], f"{quantity} at γ {r['gamma']:g}", value)
    for variant in t.variants:
        for gamma, by_seed in t.gains.get(variant, {}).items():
            if by_seed:
                record(out, env, variant, "", f"gain at γ {gamma:g}", mean(by_seed))
    for r in far_in_table_order(t):
        if r["error"]:
            where = f"tracking error {r['side']} the range"
            record(out, env, r["variant"], "", f"{where} at γ {r['gamma']:g}", mean(r["error"]))
            for quantity, key in (
                ("change", "difference"),
                ("p", "p"),
                ("p Holm", "p_holm"),
                ("detectable", "detectable"),
            ):
                if r["test"] is not None:
                    record(out, env, r["variant"], "γ 1", f"{where} {quantity} at γ {r['gamma']:g}", r["test"][key])
    return out


def far_in_table_order(t: CommandTables) -> list[dict]:
    """The rows of the table outside the training range, a variant's sides in turn."""
    return [
        r
        for variant in t.variants
        for side, _ in t.outside
        for r in t.far
        if r["variant"] == variant and r["side"] == side
    ]


def sweep_table(base: Path, env: str) -> dict | None:
    """The set's sweep on the training distribution of commands at its last step: {"last", "gammas", "rows": [{variant,
    seeds, cells: {γ: {seed: return}}, held: its heldout_gamma.csv row or None}]}; None where episodes.csv does not
    exist, and no rows where it holds none of the command task's variants."""
    if not (base / "episodes.csv").exists():
        return None
    means = seed_means(read_rows(base / "episodes.csv"))
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == env and k[1] == v for k in means)]
    if not variants:
        return {"rows": []}
    last = last_step(means, env)
    gammas = sorted({g for (e, v, s, g) in means if e == env and s == last})
    heldout = {}
    if (base / "heldout_gamma.csv").exists():
        heldout = {
            (r["variant"], int(r["step"])): r for r in read_csv(base / "heldout_gamma.csv") if r["env_id"] == env
        }
    rows = []
    for variant in variants:
        cells = cells_of(means, env, variant)
        rows.append({"variant": variant, "cells": {g: cells[(last, g)] for g in gammas if (last, g) in cells},
                     "seeds": max((len(cells[(last, g)]) for g in gammas if (last, g) in cells), default=0),
                     "held": heldout.get((variant, last))})  # fmt: skip
    return {"last": last, "gammas": gammas, "rows": rows}
