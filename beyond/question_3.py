"""Question 3's verdicts, "what these tests say, and no more": each a sentence template (text.fill) whose numbers are
looked up in the rows the section's tables gave report_values.csv, never computed here: the fitted null's fall and
return tests, its cells' gap (no test), and cloning while training on fresh episodes."""

from beyond.sets import BASELINES, BC, CLONING_VARIANTS
from beyond.text import fill
from paper_study.paper import paper_name
from paper_study.stats import ALPHA

FALLS = ("- **The fitted null and PPO's knob.** Scored on fresh episodes, γ falls less from its best value to the largest "
         "with the cloned null than with PPO's untrained one on {smaller} of {tasks} tasks ({smaller_tests}); not on "
         "the others ({other_tests}), where a negative difference is a larger fall.")  # fmt: skip
UNUSED = (" On {tasks} the cloned null's best γ is 1 (no guidance): its smaller fall is from γ = 1, not from a γ at which "
          "guidance helped.")  # fmt: skip
FALL = "{env} {difference:+.1f} points, p {p:p}, Holm {p_holm:p}"
RETURNS = ("- **Return, PPO's agents.** Tested at each side's best γ only, on fresh episodes: {survive} of {tests} tests "
           "survive Holm ({items}), so a difference below the detectable one is not ruled out. Over the sweep's γ ≠ 1 "
           "cells the cloned null's returns lie above the untrained null's on {gap_tasks} (median gap {gaps}), a gap "
           "with no test of its own: the cells share their seeds.")  # fmt: skip
RETURN = "{env} {difference:+.1f}, p {p:p}, Holm {p_holm:p}, detectable {detectable:.0f}"
GAP = "{env} {gap:+.1f}% [{low:+.1f}, {high:+.1f}]"
TRAINED = ("- **In place of a trained null.** For the γ_train 1.1 agents, {costs} of {tests} return tests at the best γ "
           "survive Holm: {items}. That is the evidence that the cloned null does not replace a trained one, on those "
           "tasks alone.")  # fmt: skip
COST = "{env} {difference:+.1f} (p {p:p}, Holm {p_holm:p})"
CLONING = ("- **Cloning while training.** On fresh episodes, with each side's best γ chosen on the sweep, the cloning "
           "variant's fall is smaller {against_ppo}; and {against_constant}, the comparison that isolates the cloning "
           "(the same γ_train). Where no test survives Holm, 5 seeds detect only differences of the size shown.")  # fmt: skip
CLONING_SIDE = "than {baseline} on {significant} of {tasks} tasks ({items})"
FRESH_FALL = "{env} {difference:+.1f} points, p {p:p}, Holm {p_holm:p}, detectable {detectable:.1f}"
# Each kind of test as report_values.csv names its quantities: (p's prefix, difference, detectable).
KINDS = {"fall": ("fall", "fall difference (pts)", "fall detectable (pts)"),
         "return": ("return", "return difference at best γ", "return detectable"),
         "fresh fall": ("fresh fall", "fresh fall difference (pts)", "fresh fall detectable (pts)")}  # fmt: skip


def question_3_reading(values_out: list[dict]) -> list[str]:
    """The section's verdicts, from the numbers its tables recorded (report_values.csv's rows)."""
    value = {(r["env_id"], r["variant"], r["baseline"], r["quantity"]): r["value"] for r in values_out}
    ppo_bc, own = "ppo" + BC, "pgg_g1.1"
    envs = list(dict.fromkeys(r["env_id"] for r in values_out if r["variant"] == ppo_bc))

    def test(env, variant, baseline, kind) -> dict | None:
        """A test's numbers as the templates name them; None where it was not made."""
        p, difference, detectable = KINDS[kind]
        if (env, variant, baseline, f"{p} p Holm") not in value:
            return None
        return {"env": env, "p": value[(env, variant, baseline, f"{p} p")],
                "p_holm": value[(env, variant, baseline, f"{p} p Holm")],
                "difference": value[(env, variant, baseline, difference)],
                "detectable": value.get((env, variant, baseline, detectable))}  # fmt: skip

    lines = []
    falls = [t for e in envs if (t := test(e, ppo_bc, "ppo", "fall"))]
    if falls:
        smaller = [t for t in falls if t["p_holm"] < ALPHA and t["difference"] > 0]
        others = [t for t in falls if t not in smaller]
        unused = [t["env"] for t in smaller if value.get((t["env"], ppo_bc, "question 3", "best γ")) == 1.0]
        lines.append(fill(FALLS, smaller=len(smaller), tasks=len(falls), smaller_tests=items(FALL, smaller) or "none",
                          other_tests=items(FALL, others))
                     + (fill(UNUSED, tasks=", ".join(unused)) if unused else ""))  # fmt: skip
    returns = [t for e in envs if (t := test(e, ppo_bc, "ppo", "return"))]
    if returns:
        gaps = [{"env": e, **{name: value[(e, ppo_bc, "ppo", f"median gap{suffix} (%)")]
                              for name, suffix in (("gap", ""), ("low", " low"), ("high", " high"))}}
                for e in envs if (e, ppo_bc, "ppo", "median gap (%)") in value
                and value[(e, ppo_bc, "ppo", "median gap low (%)")] > 0]  # fmt: skip
        lines.append(fill(RETURNS, survive=sum(t["p_holm"] < ALPHA for t in returns), tests=len(returns),
                          items=items(RETURN, returns), gap_tasks=", ".join(g["env"] for g in gaps) or "no task",
                          gaps=items(GAP, gaps) or "–"))  # fmt: skip
    trained = [t for e in envs if (t := test(e, own + BC, own, "return"))]
    if trained:
        costs = [t for t in trained if t["p_holm"] < ALPHA]
        lines.append(fill(TRAINED, costs=len(costs), tests=len(trained), items=items(COST, costs) or "none"))
    variant = next(iter(CLONING_VARIANTS))
    cloning = [(e, b) for (e, v, b, q) in value if v in CLONING_VARIANTS and q == "fresh fall p Holm"]
    if cloning:
        sides = []
        for baseline in BASELINES:
            sided = [test(e, variant, b, "fresh fall") for e, b in cloning if b == baseline]
            sides.append(fill(CLONING_SIDE, baseline=paper_name(baseline), tasks=len(sided),
                              significant=sum(t["p_holm"] < ALPHA for t in sided), items=items(FRESH_FALL, sided)))  # fmt: skip
        lines.append(fill(CLONING, against_ppo=sides[0], against_constant=sides[1]))
    return ["### Question 3: what these tests say, and no more", "", *lines, ""] if lines else []


def items(template: str, rows: list[dict]) -> str:
    """A template filled from each row, joined by semicolons."""
    return "; ".join(fill(template, **row) for row in rows)
