"""The numbers of the condition-dropout section's command part (its text: beyond/condition_dropout.py): each test
family computed once as a table (command_tables), and report_values.csv's rows written from them (command_values)."""

from beyond.cells import record
from beyond.command import gain, per_seed
from beyond.dropout_tests import (
    SECTION,
    against_gamma_one,
    against_others,
    family,
    gaps_of,
    record_family,
    record_welch,
    seeds_of,
)
from beyond.sets import COMMAND_DROPOUT, COMMAND_ENV, COMMAND_SET

# The command bands' two families: inside the training range, and outside it.
BAND_FAMILIES = (("low", "middle", "high"), ("below", "above"))


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
    return [(name, chosen[name]) for name in ("low", "middle", "high", "below", "above") if chosen[name]]


def command_tables(cells: dict, inside: dict) -> dict:
    """The command task's tables with the command dropped: each variant's tracking error, per-step error, gain and
    return over the training range at each γ against γ = 1 (a Holm family each), its error per band (the bands inside
    the range one family, those outside another), and the dropout set's change from γ = 1 against each other
    variant's in error and in gain (Welch, a family each)."""
    variants = [v for v in COMMAND_SET if any(k[0] == v for k in cells)]
    gammas, commands = sorted({g for (v, s, g, c) in cells}), sorted({c for (v, s, g, c) in cells})
    bands, in_range = command_bands(commands, inside), [c for c in commands if inside[c]]
    over_range = lambda quantity: lambda v, g: per_seed(cells, v, g, in_range, quantity)
    gains = lambda v, g: gain(cells, v, g, in_range)
    t = {"variants": variants, "gammas": gammas, "bands": bands, "in_range": in_range, "gaps": gaps_of(cells, COMMAND_DROPOUT),
         **{key: family(against_gamma_one(variants, gammas, measure)) for key, measure in
            (("error", over_range("error")), ("step_error", over_range("step_error")), ("gains", gains),
             ("returns", over_range("return")))},
         "band_families": [family([r for band_name, chosen in bands if band_name in names for r in against_gamma_one(
             variants, gammas, lambda v, g, chosen=chosen: per_seed(cells, v, g, chosen, "error"), band=band_name)])
             for names in BAND_FAMILIES],
         "knob": against_others(variants, gammas, over_range("error"), COMMAND_DROPOUT),
         "knob_gain": against_others(variants, gammas, gains, COMMAND_DROPOUT)}  # fmt: skip
    t["by_band"] = {(r["variant"], r["band"], r["gamma"]): r for rows in t["band_families"] for r in rows}
    return t


def command_values(t: dict) -> list[dict]:
    """The command part's rows of report_values.csv: whether the set is whole, each family's values and tests, the
    seeds of each variant."""
    out, env = [], COMMAND_ENV
    record(out, env, COMMAND_DROPOUT, SECTION, "whole", float(not t["gaps"]))
    for key, quantity in (("error", "tracking error"), ("step_error", "per-step error"), ("gains", "gain"),
                          ("returns", "return")):  # fmt: skip
        record_family(out, env, t[key], quantity)
    for variant in t["variants"]:
        record(out, env, variant, SECTION, "seeds", seeds_of(t["error"], variant))
    for rows in t["band_families"]:
        record_family(out, env, rows, "tracking error")
    record_welch(out, env, t["knob"], COMMAND_DROPOUT, "tracking error")
    record_welch(out, env, t["knob_gain"], COMMAND_DROPOUT, "gain")
    return out
