"""Read the paper's continuous dropout figure, which has no table, into numbers; set our figure and cells beside it.

The paper gives its continuous dropout-0.1 ablation (six MuJoCo tasks, eval γ 1.0-1.2) as a figure
only (`../shared/paper/fig_continuous_dropout0.1.png`). Its lines carry markers at 200k and 1M steps;
this finds each marker by its colour (the legend's viridis colours, anti-aliasing tolerated) and maps
its pixel row to a return through the panel's y ticks, whose pixel rows were measured on this figure.
A marker hidden under another of a near value is left blank: a guess would be a number nobody read.
The figure's black PPO markers read back the paper's PPO table to within 1% of a panel's y range
(tests/test_plots.py). The paler γ markers, blended with the CI bands, cannot be checked that way:
the paper gives no numbers for them.

    python -m paper_study.data.read_dropout_figure ../shared/paper/fig_continuous_dropout0.1.png \
        --csv paper_study/data/paper_dropout_figure.csv
    python -m paper_study.data.read_dropout_figure ../shared/paper/fig_continuous_dropout0.1.png \
        --beside results/continuous/fig_continuous_pgg_drop0.1.png \
        --output results/continuous/side_by_side_pgg_drop0.1.png \
        --ours results/continuous/episodes.csv \
        --provenance results/provenance.csv --table results/continuous/compare_paper_figure.md
"""

import csv
import io
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro
from PIL import Image
from scipy import stats

from paper_study.agreement import step_label
from paper_study.stats import holm
from paper_study.summary import read_provenance, summarise, table_csv, table_kinds
from pgg_utils.episodes import read_episodes, select_mode
from pgg_utils.files import InputError, write_atomic

FIGURE_SIZE = (2586, 1319)  # the calibration below holds for this rendering of the figure only
# (line, eval γ) -> marker colour: the dropout model's lines in the legend's viridis, and the paper's PPO
# line in black, which its table also gives and so checks the calibration (tests/test_plots.py)
LINE_COLOURS = {
    ("ppo", 1.0): (0, 0, 0),
    ("pgg_drop0.1", 1.0): (71, 42, 122),
    ("pgg_drop0.1", 1.05): (51, 98, 141),
    ("pgg_drop0.1", 1.1): (33, 145, 140),
    ("pgg_drop0.1", 1.15): (63, 188, 115),
    ("pgg_drop0.1", 1.2): (176, 221, 47),
}
COLOUR_TOLERANCE = 30  # summed |ΔRGB|; the light markers are blended with the CI bands behind them
MIN_MARKER_PIXELS = 12  # fewer matching pixels is a line passing by, not a marker
# env: (x of its 250k tick, its plotting area's pixel rows inside the axes' frame, two y ticks as
# (pixel row, return)); x ticks are 175.67 px per 250k steps
TOP_ROW, BOTTOM_ROW = (66, 568), (671, 1172)
PANELS = {
    "HalfCheetah-v4": (207, TOP_ROW, ((126, 2000.0), (521, 800.0))),
    "Hopper-v4": (949, TOP_ROW, ((102, 3000.0), (503, 1200.0))),
    "Humanoid-v4": (1690, TOP_ROW, ((114, 700.0), (420, 500.0))),
    "InvertedPendulum-v4": (207, BOTTOM_ROW, ((720, 1000.0), (1159, 700.0))),
    "Pusher-v4": (949, BOTTOM_ROW, ((734, -40.0), (1146, -100.0))),
    "Walker2d-v4": (1690, BOTTOM_ROW, ((763, 3000.0), (1052, 1000.0))),
}
PIXELS_PER_250K = 175.67
PAPER_TABLES = Path(__file__).resolve().parent / "paper_results.csv"
MARKED_STEPS = (200_000, 1_000_000)


@dataclass
class Args:
    figure: tyro.conf.Positional[Path]
    """the paper's fig_continuous_dropout0.1.png"""
    csv: Path | None = None
    """write the readings here (env_id, step, line, eval_guidance, paper_figure_mean)"""
    beside: Path | None = None
    """our figure, to be set under the paper's in one image (needs --output)"""
    output: Path | None = None
    """where the side-by-side image goes"""
    ours: tuple[Path, ...] | None = None
    """our sweeps' episodes.csv files (the dropout models', and PPO's for the effects table), summarised as
    plot_results does and tabled beside the readings (needs --table)"""
    table: Path | None = None
    """where the Markdown tables of readings against our cells go"""
    provenance: Path | None = None
    """results/provenance.csv, which names the MuJoCo of sweeps that predate the config column"""


def read_markers(pixels: np.ndarray) -> list[dict]:
    """One row per (env, marked step, line, eval γ): the return at the marker's median pixel row, or None."""
    rows = []
    for env, (x_250k, (top, bottom), ((y1, v1), (y2, v2))) in PANELS.items():
        for step in MARKED_STEPS:
            x = round(x_250k + (step - 250_000) / 250_000 * PIXELS_PER_250K)
            window = pixels[top:bottom, x - 5 : x + 6]
            for (line, gamma), colour in LINE_COLOURS.items():
                hits = np.nonzero(np.abs(window - np.array(colour)).sum(axis=2) <= COLOUR_TOLERANCE)[0]
                value = None
                if len(hits) >= MIN_MARKER_PIXELS:
                    y = top + float(np.median(hits))
                    value = round(v1 + (y - y1) * (v2 - v1) / (y2 - y1), 1)
                rows.append(
                    {"env_id": env, "step": step, "line": line, "eval_guidance": gamma, "paper_figure_mean": value}
                )
    return rows


def our_summary(episodes: tuple[Path, ...], provenance: Path | None) -> list[dict]:
    """The tables' summary (paper_study.summary: statistics over seeds per cell) of our sweeps, sampled actions, learned null."""
    try:
        rows = select_mode(read_episodes([str(p) for p in episodes], check=table_kinds), "sample", "learned")
        return summarise(rows, read_provenance(str(provenance) if provenance else None))
    except InputError as e:
        sys.exit(f"error: {e}")


def dropout_cells(summary: list[dict]) -> dict:
    """(env, step, eval γ) -> the summary row of the dropout-0.1 models; one configuration per cell."""
    cells = {}
    for row in summary:
        if row["variant"] != "pgg_drop0.1":
            continue
        key = (row["env_id"], row["step"], row["eval_guidance"])
        if key in cells:
            sys.exit(
                f"error: two configurations of the dropout models at {key}: {cells[key]['config']}, {row['config']}"
            )
        cells[key] = row
    return cells


def comparison_table(readings: list[dict], summary: list[dict]) -> str:
    """Each read marker beside our cell: our mean ± 95% CI, and whether the paper's value lies inside."""
    cells = dropout_cells(summary)
    lines = ["| task | step | eval γ | paper (read off its figure) | ours (mean ± 95% CI over seeds) | paper inside our CI |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for r in readings:
        if r["line"] != "pgg_drop0.1":
            continue
        ours = cells.get((r["env_id"], r["step"], r["eval_guidance"]))
        paper = r["paper_figure_mean"]
        paper_text = "hidden under another marker" if paper is None else f"{paper:.1f}"
        ours_text = "not run" if ours is None else f"{ours['mean']:.1f} ± {ours['ci95']:.1f}"
        inside = (
            "" if paper is None or ours is None else ("yes" if abs(paper - ours["mean"]) <= ours["ci95"] else "**no**")
        )
        lines.append(
            f"| {r['env_id']} | {step_label(r['step'])} | {r['eval_guidance']:g} | {paper_text} | {ours_text} | {inside} |"
        )
    return "\n".join(lines) + "\n"


def by_seed(row: dict) -> dict[int, float]:
    """{seed: its mean return} of a summary row (paper_study.summary.summarise), as the row writes it (4 places)."""
    return dict(zip(row["seeds"], (float(m) for m in row["seed_means"].split(";")), strict=True))


def effects_table(readings: list[dict], summary: list[dict], paper_ppo: dict, step: int = 1_000_000) -> str:
    """The paper's two claims at `step`, per task: does dropout cost return against PPO (both at γ = 1,
    Welch's t over seed means), and does guidance cost the dropout models return (γ = 1.2 − γ = 1 on
    the same checkpoints, paired by seed: mean ± 95% CI, t test). p values are Holm-corrected over
    the tasks of each column."""
    cells = dropout_cells(summary)
    read = {(r["env_id"], r["step"], r["line"], r["eval_guidance"]): r["paper_figure_mean"] for r in readings}
    rows = []
    for env in PANELS:
        at_1, at_12 = cells.get((env, step, 1.0)), cells.get((env, step, 1.2))
        if at_1 is None:
            continue
        row = {"env": env, "at_1": at_1, "welch": [], "paired": None}
        for ppo in [
            r for r in summary if (r["env_id"], r["variant"], r["step"], r["eval_guidance"]) == (env, "ppo", step, 1.0)
        ]:
            p = stats.ttest_ind(list(by_seed(at_1).values()), list(by_seed(ppo).values()), equal_var=False).pvalue
            row["welch"].append((ppo, p))
        if at_12 is not None:
            before, after = by_seed(at_1), by_seed(at_12)
            if set(before) != set(after):
                sys.exit(
                    f"error: {env} at {step}: γ 1 and 1.2 have different seeds ({sorted(before)} vs {sorted(after)})"
                )
            diffs = np.array([after[seed] - before[seed] for seed in sorted(before)])
            half = stats.t.ppf(0.975, len(diffs) - 1) * diffs.std(ddof=1) / np.sqrt(len(diffs))
            row["paired"] = (diffs.mean(), half, stats.ttest_1samp(diffs, 0.0).pvalue)
        rows.append(row)
    welch_holm = iter(holm([p for row in rows for _, p in row["welch"]]))
    paired_holm = iter(holm([row["paired"][2] for row in rows if row["paired"]]))
    lines = [(f"At {step_label(step)} steps; ours: mean ± 95% CI over seeds; p two-sided, Holm-corrected "
              "over the tasks of a column in brackets. The paper's PPO is its table's; its dropout values are read off "
              "its figure (– where a marker is hidden)."), "",
             ("| task | PPO, ours (γ = 1) | dropout, ours (γ = 1) | Welch p (Holm) | paper: PPO / dropout (γ = 1) "
              "| dropout γ = 1.2 − γ = 1, ours, paired by seed | paired p (Holm) | paper: γ = 1.2 − γ = 1 |"),
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for row in rows:
        env, at_1 = row["env"], row["at_1"]
        paper_1, paper_12 = read.get((env, step, "pgg_drop0.1", 1.0)), read.get((env, step, "pgg_drop0.1", 1.2))
        paper_shift = "–" if paper_1 is None or paper_12 is None else f"{paper_12 - paper_1:+.1f}"
        paper_cols = f"{paper_ppo.get((env, step), float('nan')):.1f} / {'–' if paper_1 is None else f'{paper_1:.1f}'}"
        shift, paired_p = "–", "–"
        if row["paired"]:
            mean, half, p = row["paired"]
            shift, paired_p = f"{mean:+.1f} ± {half:.1f}", f"{p:.3f} ({next(paired_holm):.3f})"
        for ppo, p in row["welch"] or [(None, None)]:
            if ppo is None:
                ppo_text, welch_p = "not run", "–"
            else:
                label = f" (MuJoCo {ppo['mujoco']})" if ppo["mujoco"] != at_1["mujoco"] else ""
                ppo_text, welch_p = f"{ppo['mean']:.1f} ± {ppo['ci95']:.1f}{label}", f"{p:.3f} ({next(welch_holm):.3f})"
            lines.append(f"| {env} | {ppo_text} | {at_1['mean']:.1f} ± {at_1['ci95']:.1f} | {welch_p} | {paper_cols} "
                         f"| {shift} | {paired_p} | {paper_shift} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def side_by_side(paper: Image.Image, ours: Image.Image, path: Path) -> None:
    """The paper's figure above ours, both scaled to one width, with a caption strip over each."""
    import matplotlib
    from PIL import ImageDraw, ImageFont

    font = ImageFont.truetype(str(Path(matplotlib.get_data_path(), "fonts", "ttf", "DejaVuSans.ttf")), 32)  # has a γ
    width = max(paper.width, ours.width)
    scaled = [im.resize((width, round(im.height * width / im.width))) for im in (paper, ours)]
    captions = ("The paper's figure (Qi, Tang, Zhu): continuous PPO with dropout 10%",
                "This reproduction: 5 seeds, 50 episodes per cell, the paper's eval γ 1.0-1.2")  # fmt: skip
    strip = 60
    canvas = Image.new("RGB", (width, sum(im.height + strip for im in scaled)), "white")
    draw, y = ImageDraw.Draw(canvas), 0
    for im, caption in zip(scaled, captions):
        draw.text((20, y + 15), caption, fill="black", font=font)
        canvas.paste(im.convert("RGB"), (0, y + strip))
        y += im.height + strip
    image = io.BytesIO()
    canvas.save(image, format="PNG")
    write_atomic(path, image.getvalue())


def open_image(path: Path) -> Image.Image:
    try:
        return Image.open(path)
    except (OSError, ValueError) as e:  # a missing file, or one PIL cannot read as an image
        sys.exit(f"error: cannot read {path} as an image: {e}")


def read_figure(args: Args) -> None:
    """Everything `args` asks for: the markers' CSV, the figure beside ours, the table against our cells."""
    paper = open_image(args.figure)
    if paper.size != FIGURE_SIZE:
        sys.exit(
            f"error: {args.figure} is {paper.size[0]}x{paper.size[1]}; the calibration is for the paper's {FIGURE_SIZE[0]}x{FIGURE_SIZE[1]} rendering"
        )
    if (args.beside is None) != (args.output is None):
        sys.exit("error: --beside and --output go together")
    if (args.ours is None) != (args.table is None):
        sys.exit("error: --ours and --table go together")
    for given in (args.beside, args.provenance, *(args.ours or ())):
        if given is not None and not given.is_file():
            sys.exit(f"error: no file at {given}")
    for written in (args.csv, args.output, args.table):
        if written is not None and not written.parent.is_dir():
            sys.exit(f"error: no directory {written.parent} to write {written.name} into")
    ours_figure = open_image(args.beside) if args.beside is not None else None
    rows = read_markers(np.asarray(paper.convert("RGB")).astype(int))
    if args.csv is not None:
        unread_as_nan = [
            {**r, "paper_figure_mean": math.nan if r["paper_figure_mean"] is None else r["paper_figure_mean"]}
            for r in rows
        ]
        write_atomic(args.csv, table_csv(unread_as_nan))  # NaN is written as an empty field
        print(f"wrote {args.csv} ({sum(r['paper_figure_mean'] is not None for r in rows)} of {len(rows)} markers read)")
    if args.beside is not None:
        side_by_side(paper, ours_figure, args.output)
        print(f"wrote {args.output}")
    if args.ours is not None:
        summary = our_summary(args.ours, args.provenance)
        with open(PAPER_TABLES) as f:
            paper_ppo = {
                (r["env_id"], int(r["step"])): float(r["mean"]) for r in csv.DictReader(f) if r["method"] == "ppo"
            }
        text = ("# The dropout ablation against the paper's figure\n\n## Does dropout, or guidance on top of it, cost return?\n\n"
                + effects_table(rows, summary, paper_ppo) + "\n## Every read marker beside our cell\n\n"
                + comparison_table(rows, summary))  # fmt: skip
        write_atomic(args.table, text)
        print(f"wrote {args.table}")


def main() -> None:
    read_figure(tyro.cli(Args))


if __name__ == "__main__":
    main()
