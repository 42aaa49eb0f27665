"""How the report writes a number or a name: percentages, points, seed lists and counts, a mean ± CI over seeds,
a variant with the null it is guided by; and `fill`, which writes a sentence of the report from its template and
the numbers of the tables it quotes."""

import math
import string

import numpy as np

from beyond.sets import COMMAND_VARIANTS
from paper_study.agreement import fmt_p, step_label
from paper_study.paper import paper_name
from pgg_utils.episodes import mean_ci95


def pct(x: float, decimals: int = 1) -> str:
    return "–" if math.isnan(x) else f"{100 * x:+.{decimals}f}%"


def seed_list(seeds: list[int] | None) -> str:
    return "n/a" if seeds is None else ", ".join(map(str, seeds)) or "none"


def points(x: float, sign: bool = True) -> str:
    """A difference of two percentages, in percentage points."""
    return "–" if math.isnan(x) else f"{100 * x:{'+' if sign else ''}.1f} pts"


def count_of(seeds: list[int] | None, of: int) -> str:
    return "n/a" if seeds is None else f"{len(seeds)} of {of}"


def seeds_cell(values: dict, digits: int = 2) -> str:
    if not values:
        return "–"
    mean, half, _, _ = mean_ci95(list(values.values()))
    return f"{mean:.{digits}f} ± {half:.{digits}f}" if len(values) > 1 else f"{mean:.{digits}f}"


def command_name(variant: str) -> str:
    """A variant of the command set as its tables name it: the paper's name and the null it is guided by."""
    return f"{paper_name(variant)} ({COMMAND_VARIANTS[variant]})"


def name(variant: str, nulls: dict) -> str:
    return f"{paper_name(variant)} ({nulls[variant]})"


def marks(steps: dict, variants: list[str]) -> str:
    """ "At 1M" where every variant's last mark is one step, else each variant's."""
    if len({steps[v] for v in variants}) == 1:
        return f"At {step_label(steps[variants[0]])}"
    return (
        "At each variant's last mark (" + "; ".join(f"{paper_name(v)}: {step_label(steps[v])}" for v in variants) + ")"
    )


def change_cell(values: dict | None, test: dict | None, digits: int) -> str:
    """A cell of a measure at one γ: its mean over seeds, and against γ = 1 its change, Holm p and the change one test
    detects (where tested); – where there is no value."""
    if not values:
        return "–"
    mean = float(np.mean(list(values.values())))
    if test is None:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ({test['difference']:+.{digits}f}, {fmt_p(test['p_holm'])}; {test['detectable']:.{digits}f})"


class _Sentence(string.Formatter):
    """Python's format specs, and the report's own: `:p` a p value as the tables write it (agreement.fmt_p), `:gs` a
    list of numbers as "0.5, 1, 2" ("none" for an empty list), `:pct` a fraction as a signed percentage."""

    def format_field(self, value, spec: str) -> str:
        if spec == "p":
            return fmt_p(value)
        if spec == "gs":
            return ", ".join(f"{x:g}" for x in value) or "none"
        if spec == "pct":
            return pct(value)
        return super().format_field(value, spec)


def fill(template: str, **values) -> str:
    """A sentence of the report: `template`'s fields filled from `values`, the numbers of the tables it quotes (looked
    up, never computed here), with the format specs of _Sentence."""
    return _Sentence().format(template, **values)
