"""Regenerate the paper's tables and figures from γ-sweep CSVs, with the paper's numbers beside ours.

    python plot_results.py sweeps/discrete --runs runs/discrete --compare-paper --output results/discrete

Reads the episodes.csv of one or more sweeps (eval_gamma_sweep.py) and, with --runs, the runs'
TensorBoard events. Every statistic is the one of eval_gamma_sweep.mean_ci95: per training seed the
mean return over the evaluation episodes, then across seeds the mean and a Student-t 95% confidence
interval. Tables and figures show the same numbers.

Writes into --output (and prints each path):
  table_<kind>.md / .tex        the paper's appendix layout: per checkpoint step a PPO row (eval γ=1)
                                and one row per eval γ for each guided variant; one column per env
  table_<kind>_ppo_sweep.*      the vanilla PPO checkpoints swept over γ (not in the paper)
  fig_<kind>_<variant>.png/pdf  the paper's figures: return against training steps, PPO solid black,
                                one dashed viridis line per eval γ, 95% CI as band and error bars
  gamma_response_<kind>.png/pdf return against eval γ at one step, one line per variant
  learning_curves.png/pdf       (--runs) episodic training return against steps, mean and CI over seeds
  best_gamma.md / .csv          the best eval γ per env, variant and step
  aggregate_iqm.md / .csv       interquartile mean over envs and seeds of min-max normalised scores,
                                with stratified-bootstrap 95% CIs (scipy.stats.bootstrap)
  compare_paper.md / .csv       (--compare-paper) our cells beside the paper's; flags every cell whose
                                CI does not overlap the paper's
  controls.md                   when the sweeps hold several evaluation modes (--deterministic,
                                --uniform-null): the modes side by side, cell by cell
"""

import csv
import json
import math
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import tyro  # noqa: E402
from scipy import stats  # noqa: E402

from eval_gamma_sweep import mean_ci95, summarise, variant_label  # noqa: E402

PAPER_DATA = Path(__file__).resolve().parent / "data" / "paper_results.csv"
REQUIRED_COLUMNS = {"env_id", "variant", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy",
                    "null_branch", "seed", "return"}  # fmt: skip
PAPER_METHOD_OF_VARIANT = {"ppo": ("ppo", ""), "pgg_g1.1": ("pgg", "1.1")}


@dataclass
class Args:
    sweeps: tyro.conf.Positional[tuple[str, ...]]
    """sweep output directories (holding episodes.csv) or episodes.csv files"""
    output: str = "results"
    """directory for every table and figure"""
    runs: tuple[str, ...] = ()
    """run directories or roots whose TensorBoard events give the learning curves"""
    compare_paper: bool = False
    """put the paper's published numbers (data/paper_results.csv) beside ours and flag disagreements"""
    response_step: int | None = None
    """checkpoint step of the γ-response plot; default the last step of each env"""
    policy: str = "sample"
    """which evaluation policy to report: sample or deterministic"""
    null_branch: str = "learned"
    """which unconditional branch to report: learned or uniform (the temperature-scaling control)"""


class InputError(Exception):
    """Bad input: reported as one line, exit status 2."""


def read_episodes(paths) -> list[dict]:
    rows = []
    for raw in paths:
        path = Path(raw)
        path = path / "episodes.csv" if path.is_dir() else path
        if not path.exists():
            raise InputError(f"no sweep CSV at {path}")
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is None:
                raise InputError(f"{path} is empty")
            missing = REQUIRED_COLUMNS - set(reader.fieldnames or [])
            if missing:
                raise InputError(f"{path} lacks columns {sorted(missing)}; is it an episodes.csv of eval_gamma_sweep.py?")
            rows.extend(reader)
    return rows


def select_mode(rows: list[dict], policy: str, null_branch: str) -> list[dict]:
    selected = [r for r in rows if r["policy"] == policy and r["null_branch"] == null_branch]
    if not selected:
        raise InputError(f"no episodes with policy={policy} and null_branch={null_branch}")
    return selected


def controls_table(summary_all: list[dict]) -> str:
    """The evaluation modes side by side (sampled or deterministic, learned or uniform null branch),
    on the cells that more than one mode evaluated."""
    modes = sorted({(r["policy"], r["null_branch"]) for r in summary_all})
    by_cell = defaultdict(dict)
    for r in summary_all:
        by_cell[(r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"]))][(r["policy"], r["null_branch"])] = r
    lines = ["| env | variant | step | eval γ | " + " | ".join(f"{p}, {n} null" for p, n in modes) + " |",
             "|---|---|---|---|" + "---|" * len(modes)]  # fmt: skip
    for (env, variant, step, gamma), cells in sorted(by_cell.items()):
        if len(cells) > 1:
            values = [fmt_cell(cells.get(mode), latex=False) for mode in modes]
            lines.append(f"| {env} | {variant} | {step_label(step)} | {gamma:g} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def kind_of(env_id: str) -> str:
    """Groups envs into the paper's two tables: the MuJoCo tasks are the -v4/-v5 ones."""
    return "continuous" if env_id.endswith(("-v4", "-v5")) else "discrete"


def cell_index(summary: list[dict]) -> dict:
    """(env, variant, step, eval γ) -> summary row."""
    return {(r["env_id"], r["variant"], int(r["step"]), float(r["eval_guidance"])): r for r in summary}


def fmt_cell(row: dict | None, latex: bool) -> str:
    if row is None:
        return ""
    mean, ci = float(row["mean"]), float(row["ci95"])
    text = f"{mean:.1f}" if math.isnan(ci) else (f"{mean:.1f} \\pm {ci:.1f}" if latex else f"{mean:.1f} ± {ci:.1f}")
    return f"${text}$" if latex else text


def step_label(step: int) -> str:
    return f"{step // 1_000_000}M" if step % 1_000_000 == 0 else f"{step // 1000}k"


def gamma_label(gamma: float, latex: bool) -> str:
    return f"$\\gamma={gamma:g}$" if latex else f"γ={gamma:g}"


def table_rows(summary: list[dict], envs: list[str], ppo_sweep: bool, latex: bool):
    """Yields ("section", label) or ("row", label, cells) in the paper's appendix layout."""
    cells = cell_index(summary)
    steps = sorted({int(r["step"]) for r in summary})
    variants = sorted({r["variant"] for r in summary if r["variant"] != "ppo"})
    gammas_of = defaultdict(set)
    for r in summary:
        gammas_of[r["variant"]].add(float(r["eval_guidance"]))
    for step in steps:
        yield ("section", f"{step_label(step)} Steps")
        if ppo_sweep:
            for gamma in sorted(gammas_of["ppo"]):
                yield ("row", gamma_label(gamma, latex), [fmt_cell(cells.get((e, "ppo", step, gamma)), latex) for e in envs])
            continue
        if (("ppo" in gammas_of) and any((e, "ppo", step, 1.0) in cells for e in envs)):
            yield ("row", "PPO", [fmt_cell(cells.get((e, "ppo", step, 1.0)), latex) for e in envs])
        for variant in variants:
            yield ("row", variant.replace("_", "\\_") if latex else variant, None)
            for gamma in sorted(gammas_of[variant]):
                label = ("\\quad " if latex else "  ") + gamma_label(gamma, latex)
                yield ("row", label, [fmt_cell(cells.get((e, variant, step, gamma)), latex) for e in envs])


def markdown_table(summary, envs, ppo_sweep=False, title="") -> str:
    lines = [f"**{title}** (mean ± 95% CI over seeds)", "", "| Method | " + " | ".join(envs) + " |",
             "|---|" + "---|" * len(envs)]  # fmt: skip
    for item in table_rows(summary, envs, ppo_sweep, latex=False):
        if item[0] == "section":
            lines.append(f"| **{item[1]}** |" + " |" * len(envs))
        else:
            lines.append(f"| {item[1]} | " + " | ".join(item[2] or [""] * len(envs)) + " |")
    return "\n".join(lines) + "\n"


def latex_table(summary, envs, ppo_sweep=False, title="") -> str:
    columns = len(envs) + 1
    body = []
    for item in table_rows(summary, envs, ppo_sweep, latex=True):
        if item[0] == "section":
            body += ["\\midrule", f"\\multicolumn{{{columns}}}{{l}}{{\\textbf{{{item[1]}}}}} \\\\"]
        else:
            body.append(" & ".join([item[1], *(item[2] or [""] * len(envs))]) + " \\\\")
    header = " & ".join(["Method", *envs]) + " \\\\"
    return "\n".join([
        "\\documentclass{article}", "\\usepackage{booktabs}", "\\usepackage[margin=1cm,landscape]{geometry}",
        "\\begin{document}", "\\begin{table}[h]", "\\centering", "\\small",
        f"\\caption{{{title}: mean $\\pm$ 95\\% CI over seeds}}",
        f"\\begin{{tabular}}{{l{'c' * len(envs)}}}", "\\toprule", header, *body, "\\bottomrule", "\\end{tabular}",
        "\\end{table}", "\\end{document}", "",
    ])  # fmt: skip


def write(path: Path, text: str, written: list) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    written.append(path)


def write_csv(path: Path, rows: list[dict], written: list) -> None:
    columns = list(rows[0]) if rows else ["empty"]
    lines = [",".join(columns)] + [",".join(str(r[c]) for c in columns) for r in rows]
    write(path, "\n".join(lines) + "\n", written)


def save_figure(fig, stem: Path, written: list) -> None:
    stem.parent.mkdir(parents=True, exist_ok=True)
    for suffix in (".png", ".pdf"):
        path = stem.parent / (stem.name + suffix)  # not with_suffix: "pgg_g1.1" would lose ".1"
        fig.savefig(path, dpi=200, bbox_inches="tight", metadata={"CreationDate": None} if suffix == ".pdf" else None)
        written.append(path)
    plt.close(fig)


def panels(n: int):
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()[:n]


def plot_series(ax, xs, rows, errorbars=True, **style):
    """A line of means with its 95% CI as a band and, at the points, error bars."""
    means = np.array([float(r["mean"]) for r in rows])
    cis = np.nan_to_num(np.array([float(r["ci95"]) for r in rows]))
    (line,) = ax.plot(xs, means, **style)
    ax.fill_between(xs, means - cis, means + cis, color=line.get_color(), alpha=0.12, linewidth=0)
    if errorbars:
        ax.errorbar(xs, means, yerr=cis, fmt="none", ecolor=line.get_color(), capsize=2, linewidth=0.8)
    return line


def steps_formatter(x, _pos) -> str:
    return f"{x / 1e6:g}M" if x >= 1e6 else f"{x / 1e3:g}K" if x else "0"


def style_axis(ax, title: str, xlabel: str, ylabel: str, steps_on_x: bool) -> None:
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    if steps_on_x:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(steps_formatter))


def fit_y_to_means(ax, rows) -> None:
    """With very few seeds a t interval can dwarf the data (t_{0.975,1} = 12.7): then the axis follows
    the means, and the bands run off it; the tables carry the full intervals."""
    means = np.array([float(r["mean"]) for r in rows])
    cis = np.nan_to_num(np.array([float(r["ci95"]) for r in rows]))
    lo, hi = means.min(), means.max()
    span = (hi - lo) or abs(hi) or 1.0
    if (means + cis).max() - (means - cis).min() > 3 * span:
        ax.set_ylim(lo - 0.25 * span, hi + 0.25 * span)


def seeds_label(rows) -> str:
    counts = sorted({int(r["n_seeds"]) for r in rows})
    text = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    return f"{text} seed" + ("" if text == "1" else "s")


def shared_legend(fig, ax) -> None:
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, frameon=False,
               title="lines ± 95% CI", title_fontsize=7)  # fmt: skip


def figure_for_variant(summary, envs, variant):
    """The paper's figure: return against training steps per env; PPO solid black (eval γ=1), one
    dashed line per eval γ of `variant`, viridis from low to high γ."""
    cells = cell_index(summary)
    gammas = sorted({float(r["eval_guidance"]) for r in summary if r["variant"] == variant})
    colours = plt.get_cmap("viridis")(np.linspace(0, 0.9, len(gammas)))
    fig, axes = panels(len(envs))
    for ax, env in zip(axes, envs):
        steps = sorted({int(r["step"]) for r in summary if r["env_id"] == env})
        ppo = [cells.get((env, "ppo", s, 1.0)) for s in steps]
        if all(ppo):
            plot_series(ax, steps, ppo, color="black", linestyle="-", marker="o", markersize=3, label="PPO")
        for gamma, colour in zip(gammas, colours):
            series = [cells.get((env, variant, s, gamma)) for s in steps]
            if all(series):
                plot_series(ax, steps, series, color=colour, linestyle="--", marker="o", markersize=2.5,
                            label=f"γ={gamma:g}")  # fmt: skip
        env_rows = [r for r in summary if r["env_id"] == env and (r["variant"] == variant or r["variant"] == "ppo")]
        style_axis(ax, f"{env} ({seeds_label(env_rows)})", "training steps", "return", steps_on_x=True)
        fit_y_to_means(ax, env_rows)
    fig.suptitle(f"{variant} checkpoints, eval guidance swept", fontsize=9)
    fig.tight_layout()
    shared_legend(fig, axes[0])
    return fig


def gamma_response(summary, envs, step):
    fig, axes = panels(len(envs))
    for ax, env in zip(axes, envs):
        env_rows = [r for r in summary if r["env_id"] == env]
        at = step if step is not None else max(int(r["step"]) for r in env_rows)
        for variant in sorted({r["variant"] for r in env_rows}):
            series = sorted((r for r in env_rows if r["variant"] == variant and int(r["step"]) == at),
                            key=lambda r: float(r["eval_guidance"]))  # fmt: skip
            if series:
                plot_series(ax, [float(r["eval_guidance"]) for r in series], series, marker="o", markersize=3,
                            color="black" if variant == "ppo" else None, label=variant)  # fmt: skip
        ax.set_xscale("log")
        # Ticks at the swept γ only: over 1–1.5 a log axis otherwise labels its minor ticks in ×10⁰ form.
        swept = sorted({float(r["eval_guidance"]) for r in env_rows})
        ax.set_xticks(swept, labels=[f"{g:g}" for g in swept])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        style_axis(ax, f"{env} at {step_label(at)} steps", "eval guidance γ", "return", steps_on_x=False)
    fig.tight_layout()
    shared_legend(fig, axes[0])
    return fig


def learning_curves(run_paths, output, written, bins: int = 50) -> None:
    """Episodic training return (TensorBoard charts/episodic_return), binned over steps, per variant:
    mean over seeds of each seed's bin mean, with the t 95% CI."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    curves = defaultdict(list)  # (env, variant) -> [(steps, returns)] per seed
    for raw in run_paths:
        for args_file in sorted(Path(raw).rglob("args.json")):
            run_args = json.loads(args_file.read_text())
            accumulator = EventAccumulator(str(args_file.parent), size_guidance={"scalars": 0})
            accumulator.Reload()
            if "charts/episodic_return" not in accumulator.Tags()["scalars"]:
                continue
            events = accumulator.Scalars("charts/episodic_return")
            key = (run_args["env_id"], variant_label(run_args["guidance"], run_args["cond_dropout"]))
            curves[key].append((np.array([e.step for e in events]), np.array([e.value for e in events])))
    if not curves:
        raise InputError(f"no TensorBoard episodic returns under {list(run_paths)}")
    envs = sorted({env for env, _ in curves})
    fig, axes = panels(len(envs))
    for ax, env in zip(axes, envs):
        for (curve_env, variant), seeds in sorted(curves.items()):
            if curve_env != env:
                continue
            edges = np.linspace(0, max(s.max() for s, _ in seeds) + 1, bins + 1)
            per_seed = np.array([[r[(s >= lo) & (s < hi)].mean() if ((s >= lo) & (s < hi)).any() else np.nan
                                  for lo, hi in zip(edges[:-1], edges[1:])] for s, r in seeds])  # fmt: skip
            centres = (edges[:-1] + edges[1:]) / 2
            stats_per_bin = [mean_ci95(col[~np.isnan(col)]) if (~np.isnan(col)).any() else (np.nan,) * 4 for col in per_seed.T]
            rows = [{"mean": m, "ci95": h} for m, h, _, _ in stats_per_bin]
            plot_series(ax, centres, rows, errorbars=False, color="black" if variant == "ppo" else None, linewidth=1,
                        label=f"{variant} (n={len(seeds)})")  # fmt: skip
        style_axis(ax, env, "training steps", "episodic return", steps_on_x=True)
        ax.legend(fontsize=6, frameon=False)
    fig.tight_layout()
    save_figure(fig, output / "learning_curves", written)


def best_gamma(summary) -> list[dict]:
    best = {}
    for r in summary:
        key = (r["env_id"], r["variant"], int(r["step"]))
        if key not in best or float(r["mean"]) > float(best[key]["mean"]):
            best[key] = r
    return [{"env_id": k[0], "variant": k[1], "step": k[2], "best_eval_guidance": float(r["eval_guidance"]),
             "mean": r["mean"], "ci95": r["ci95"]} for k, r in sorted(best.items())]  # fmt: skip


def iqm(scores: np.ndarray) -> float:
    return float(stats.trim_mean(scores, 0.25))


def aggregate_iqm(summary) -> list[dict]:
    """Per (variant, step, eval γ): IQM over (env, seed) of per-seed mean returns, min-max normalised per
    env and step over all cells of the sweep (0 = worst cell mean, 1 = best). 95% CI by a stratified
    percentile bootstrap: seeds are resampled within each env (scipy.stats.bootstrap, one sample per env)."""
    bounds = {}
    for r in summary:
        key = (r["env_id"], int(r["step"]))
        lo, hi = bounds.get(key, (math.inf, -math.inf))
        bounds[key] = (min(lo, float(r["mean"])), max(hi, float(r["mean"])))
    groups = defaultdict(list)
    for r in summary:
        lo, hi = bounds[(r["env_id"], int(r["step"]))]
        seed_means = np.array([float(x) for x in r["seed_means"].split(";")])
        groups[(r["variant"], int(r["step"]), float(r["eval_guidance"]))].append((seed_means - lo) / ((hi - lo) or 1.0))
    out = []
    for (variant, step, gamma), per_env in sorted(groups.items()):
        point = iqm(np.concatenate(per_env))
        low = high = math.nan
        if all(len(s) >= 2 for s in per_env):
            result = stats.bootstrap(tuple(per_env), lambda *envs: iqm(np.concatenate(envs)), vectorized=False,
                                     n_resamples=2000, method="percentile", random_state=0)  # fmt: skip
            low, high = result.confidence_interval
        out.append({"variant": variant, "step": step, "eval_guidance": gamma, "n_envs": len(per_env),
                    "iqm": round(point, 4), "ci_low": round(float(low), 4), "ci_high": round(float(high), 4)})  # fmt: skip
    return out


def compare_with_paper(summary) -> list[dict]:
    """Our cells beside the paper's. `agrees` is False where the two 95% CIs do not overlap."""
    with open(PAPER_DATA, newline="") as f:
        paper = list(csv.DictReader(f))
    ours = cell_index(summary)
    paper_envs = {p["env_id"] for p in paper}
    absent = sorted({r["env_id"] for r in summary} - paper_envs)
    for env in absent:
        print(f"note: {env} is not in the paper's tables; left out of the comparison", file=sys.stderr)
    if len(absent) == len({r["env_id"] for r in summary}):
        raise InputError(f"none of the swept envs ({', '.join(absent)}) is in the paper's tables")
    out = []
    for variant, (method, train_guidance) in PAPER_METHOD_OF_VARIANT.items():
        for p in paper:
            if p["method"] != method or p["train_guidance"] != train_guidance:
                continue
            key = (p["env_id"], variant, int(p["step"]), float(p["eval_guidance"]))
            if key not in ours:
                continue
            mine = ours[key]
            gap = abs(float(mine["mean"]) - float(p["mean"]))
            ci = float(mine["ci95"])
            agrees = "n/a" if math.isnan(ci) else str(gap <= ci + float(p["ci95"]))
            out.append({"env_id": key[0], "variant": variant, "step": key[2], "eval_guidance": key[3],
                        "paper_mean": float(p["mean"]), "paper_ci95": float(p["ci95"]),
                        "our_mean": float(mine["mean"]), "our_ci95": ci, "our_seeds": mine["n_seeds"],
                        "agrees": agrees})  # fmt: skip
    return out


def comparison_markdown(rows) -> str:
    flagged = [r for r in rows if r["agrees"] == "False"]
    lines = [f"{len(rows)} cells compared; **{len(flagged)} disagree** (95% CIs do not overlap), marked ✗.", "",
             "| env | variant | step | eval γ | paper | ours | seeds | |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        mark = {"True": "✓", "False": "✗", "n/a": "?"}[r["agrees"]]
        lines.append(f"| {r['env_id']} | {r['variant']} | {step_label(r['step'])} | {r['eval_guidance']:g} | "
                     f"{r['paper_mean']:.1f} ± {r['paper_ci95']:.1f} | {r['our_mean']:.1f} ± {r['our_ci95']:.1f} | "
                     f"{r['our_seeds']} | {mark} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def simple_markdown(rows: list[dict]) -> str:
    columns = list(rows[0])
    return "\n".join(["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
                     + ["| " + " | ".join(str(r[c]) for c in columns) + " |" for r in rows]) + "\n"  # fmt: skip


def generate(args: Args) -> list[Path]:
    output = Path(args.output)
    episodes = read_episodes(args.sweeps)
    summary = summarise(select_mode(episodes, args.policy, args.null_branch))
    written: list[Path] = []
    if len({(r["policy"], r["null_branch"]) for r in episodes}) > 1:
        write(output / "controls.md", controls_table(summarise(episodes)), written)
    by_kind = defaultdict(list)
    for r in summary:
        by_kind[kind_of(r["env_id"])].append(r)
    for kind, rows in sorted(by_kind.items()):
        envs = sorted({r["env_id"] for r in rows})
        title = f"{kind.capitalize()} environments"
        write(output / f"table_{kind}.md", markdown_table(rows, envs, title=title), written)
        write(output / f"table_{kind}.tex", latex_table(rows, envs, title=title), written)
        ppo_gammas = {float(r["eval_guidance"]) for r in rows if r["variant"] == "ppo"}
        if len(ppo_gammas) > 1:
            title = f"Vanilla PPO checkpoints swept over eval guidance ({kind})"
            write(output / f"table_{kind}_ppo_sweep.md", markdown_table(rows, envs, ppo_sweep=True, title=title), written)
            write(output / f"table_{kind}_ppo_sweep.tex", latex_table(rows, envs, ppo_sweep=True, title=title), written)
        for variant in sorted({r["variant"] for r in rows}):
            save_figure(figure_for_variant(rows, envs, variant), output / f"fig_{kind}_{variant}", written)
        save_figure(gamma_response(rows, envs, args.response_step), output / f"gamma_response_{kind}", written)
    best = best_gamma(summary)
    write_csv(output / "best_gamma.csv", best, written)
    write(output / "best_gamma.md", simple_markdown(best), written)
    aggregate = aggregate_iqm(summary)
    write_csv(output / "aggregate_iqm.csv", aggregate, written)
    write(output / "aggregate_iqm.md", simple_markdown(aggregate), written)
    if args.runs:
        learning_curves(args.runs, output, written)
    if args.compare_paper:
        comparison = compare_with_paper(summary)
        write_csv(output / "compare_paper.csv", comparison, written)
        write(output / "compare_paper.md", comparison_markdown(comparison) if comparison else "no common cells\n", written)
    return written


def main() -> None:
    args = tyro.cli(Args)
    try:
        written = generate(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    for path in written:
        print(path)


if __name__ == "__main__":
    main()
