"""The figures of plot_results.py, drawn from its summary rows (one row per configuration, step and
eval γ; paper_study.summary.summarise), in one palette: one colour per training variant, one colour and marker
per eval γ, the y-axis never past a task's possible return. figure_for_variant, gamma_response and
learning_curves each return a figure; render turns one into PNG and PDF bytes, which plot_results writes.
No torch; the matplotlib backend is the caller's (plot_results sets Agg)."""

import io
import itertools
import math
import pickle
import zlib
from pathlib import Path

import matplotlib.colors
import matplotlib.figure
import matplotlib.lines
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

from paper_study.agreement import other_mujoco, step_label
from paper_study.paper import PAPER_ENVS, PAPER_GAMMAS, paper_name, series_name, variant_rank, with_series
from pgg_utils.episodes import (
    RETURN_RANGE,  # the possible return of a task: axes never extend past it
    mean_ci95,
)

MARKERS = "osD^vPX*hp<>"
# The palette, the same in every figure: one colour per training variant (PPO black, the paper's two PGG
# variants fixed, any other a fixed colour of its name) and one per eval γ. An eval γ takes the colour the
# paper's figures give it: viridis by its place in the γ set of the paper's figure of its kind (between
# them by log γ), the span measured on the paper's figures' legend colours. The continuous figure draws
# only 1.0-1.2; the table's other γ (1.25, 1.3, 1.5) take plasma's magentas, which no other line uses.
VARIANT_COLOURS = {"ppo": "black", "pgg_g1.1": "C1", "pgg_drop0.1": "C2"}
OTHER_VARIANT_COLOURS = ("C0", "C3", "C4", "C5", "C6", "C8", "C9")
GAMMA_CMAP, GAMMA_CMAP_SPAN = (
    "viridis",
    (0.12, 0.88),
)  # the paper's: dark purple for γ = 1, yellow-green for its largest
PAPER_FIGURE_GAMMAS = {"discrete": PAPER_GAMMAS["discrete"], "continuous": (1.0, 1.05, 1.1, 1.15, 1.2)}
BEYOND_FIGURE_CMAP, BEYOND_FIGURE_SPAN = "plasma", (0.3, 0.55)
# The y-limits of the paper's continuous dropout figure's panels (read off its axes with the calibration
# of paper_study/data/read_dropout_figure.py): our figure beside it uses them, widened where our means need it.
PAPER_DROPOUT_FIGURE_YLIM = {"HalfCheetah-v4": (657.0, 2182.0), "Hopper-v4": (908.0, 3162.0),
                             "Humanoid-v4": (403.0, 731.0), "InvertedPendulum-v4": (691.0, 1034.0),
                             "Pusher-v4": (-104.0, -31.0), "Walker2d-v4": (170.0, 3637.0)}  # fmt: skip
# Fonts about as large, once a figure is scaled to the paper's width, as the paper's.
TITLE_SIZE, LABEL_SIZE, TICK_SIZE, LEGEND_SIZE = 11, 10, 9, 9
LINE_STYLES = ("-", "--", ":", "-.")  # several configurations of one variant in one colour


# --- the summary rows, as figures and tables look them up -----------------------------------------


def ordered_series(summary, variant: str | None = None) -> list[tuple[str, str]]:
    """The (variant, series) pairs of the rows (of one variant, if given), in the paper's order."""
    found = {(r["variant"], r["series"]) for r in summary if variant is None or r["variant"] == variant}
    return sorted(found, key=lambda vs: (variant_rank(vs[0]), vs[0], vs[1]))


def cell_index(summary: list[dict]) -> dict:
    """(env, variant, series, step, eval γ) -> summary row."""
    return {(r["env_id"], r["variant"], r["series"], int(r["step"]), float(r["eval_guidance"])): r for r in summary}


# --- drawing -------------------------------------------------------------------------------------


def render(fig) -> dict[str, bytes]:
    """{"png": ..., "pdf": ...}: the figure rendered in memory (the PDF without a date, so that it
    regenerates bit for bit), and closed."""
    separate_titles(fig)
    images = {}
    for image_format, metadata in (("png", None), ("pdf", {"CreationDate": None})):
        image = io.BytesIO()
        fig.savefig(image, format=image_format, dpi=200, bbox_inches="tight", metadata=metadata)
        images[image_format] = image.getvalue()
    plt.close(fig)
    return images


def separate_titles(fig) -> None:
    """Breaks the titles of side-by-side panels that would overlap (a long task name with its notes)
    onto two lines, before the parenthesis of their notes, else before their last comma. The overlap
    is measured on a laid-out copy of the figure: a figure whose titles fit is not touched, and draws
    exactly as before."""
    for _ in range(3):  # a broken title can still be too wide: break it again
        laid_out = pickle.loads(pickle.dumps(fig))
        laid_out.draw_without_rendering()
        renderer = laid_out.canvas.get_renderer()
        boxes = [ax.title.get_window_extent(renderer) if ax.get_visible() and ax.get_title() else None
                 for ax in laid_out.axes]  # fmt: skip
        plt.close(laid_out)
        crowded = {i for i, a in enumerate(boxes) for j, b in enumerate(boxes) if i != j and a and b and a.overlaps(b)}
        if not [i for i in sorted(crowded) if break_title(fig.axes[i].title)]:
            return


def break_title(title) -> bool:
    """Breaks the widest line of a title once (separate_titles); False where it has no place to break."""
    lines = title.get_text().split("\n")
    widest = max(range(len(lines)), key=lambda i: len(lines[i]))
    line = lines[widest]
    at, skip = (line.index(" ("), 1) if " (" in line else (line.rfind(", "), 2)
    if at <= 0:
        return False
    lines[widest : widest + 1] = [line[: at + (1 if skip == 2 else 0)], line[at + skip :]]
    title.set_text("\n".join(lines))
    return True


def panels(n: int, cols: int | None = None):
    """A figure of `n` panels, `cols` (default up to 3) to a row, the grid's spare axes hidden."""
    cols = cols or min(n, 3)
    rows = math.ceil(n / cols)
    size = (4.4, 3.2) if n == 1 else (3.4 * cols, 2.7 * rows)  # a lone panel next to a legend needs room
    fig, axes = plt.subplots(rows, cols, figsize=size, squeeze=False, layout="constrained")
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, list(axes.ravel()[:n])


def plot_series(ax, xs, rows, errorbars=True, band_alpha=0.12, **style):
    """A line of means with its 95% CI as a band and, at the points, error bars. Returns the line and
    (xs, means, half-widths) for marking clipped bands."""
    xs = np.asarray(xs, dtype=float)
    means = np.array([float(r["mean"]) for r in rows])
    cis = np.nan_to_num(np.array([float(r["ci95"]) for r in rows]))
    (line,) = ax.plot(xs, means, **style)
    ax.fill_between(xs, means - cis, means + cis, color=line.get_color(), alpha=band_alpha, linewidth=0)
    if errorbars:
        ax.errorbar(xs, means, yerr=cis, fmt="none", ecolor=line.get_color(), capsize=2, linewidth=0.8, alpha=0.8)
    return line, (xs, means, cis, line.get_color())


def steps_formatter(x, _pos) -> str:
    return f"{x / 1e6:g}M" if x >= 1e6 else f"{x / 1e3:g}K" if x else "0"


def style_axis(ax, title: str, xlabel: str, ylabel: str, steps_on_x: bool) -> None:
    ax.set_title(title, fontsize=TITLE_SIZE)
    ax.set_xlabel(xlabel, fontsize=LABEL_SIZE)
    ax.set_ylabel(ylabel, fontsize=LABEL_SIZE)
    ax.tick_params(labelsize=TICK_SIZE)
    ax.grid(alpha=0.3)
    if isinstance(ax.yaxis.get_major_formatter(), matplotlib.ticker.ScalarFormatter):
        ax.yaxis.get_major_formatter().set_useOffset(False)  # a flat line reads 500, not 0 + 5e2
    if steps_on_x:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(steps_formatter))


def not_run(ax, env: str) -> None:
    ax.text(0.5, 0.5, "not run", ha="center", va="center", transform=ax.transAxes, fontsize=10, color="0.45")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_color("0.8")
    ax.set_title(env, fontsize=TITLE_SIZE)


def set_y_range(ax, env: str, drawn: list, few: bool = False, fixed: tuple | None = None) -> bool:
    """Fits the y-axis to the data, but never past the task's possible returns, and, with fewer than 3
    seeds where the bands dwarf the means (t_{0.975,1} = 12.7), to the means; or, given `fixed` (a
    figure's limits to match), to those, widened to hold every mean. Marks every band that runs past the
    axis with a triangle at the edge. Returns whether any band was clipped."""
    if not drawn:
        return False
    if fixed is not None:
        means = np.concatenate([d[1] for d in drawn])
        pad, m_lo, m_hi = 0.03 * (fixed[1] - fixed[0]), float(np.nanmin(means)), float(np.nanmax(means))
        lo = fixed[0] if m_lo >= fixed[0] else m_lo - pad
        hi = fixed[1] if m_hi <= fixed[1] else m_hi + pad
        return mark_clipped(ax, drawn, lo, hi)
    means = np.concatenate([d[1] for d in drawn])
    cis = np.concatenate([d[2] for d in drawn])
    lo, hi = float(np.nanmin(means - cis)), float(np.nanmax(means + cis))
    m_lo, m_hi = float(np.nanmin(means)), float(np.nanmax(means))
    span = (m_hi - m_lo) or abs(m_hi) or 1.0
    if few and hi - lo > 3 * span:
        lo, hi = m_lo - 0.3 * span, m_hi + 0.3 * span
    pad = 0.05 * ((hi - lo) or 1.0)
    lo, hi = lo - pad, hi + pad
    if env in RETURN_RANGE:
        r_lo, r_hi = RETURN_RANGE[env]
        r_pad = 0.03 * (r_hi - r_lo)
        lo, hi = max(lo, r_lo - r_pad), min(hi, r_hi + r_pad)
    return mark_clipped(ax, drawn, lo, hi)


def mark_clipped(ax, drawn: list, lo: float, hi: float) -> bool:
    """Sets the y-limits and marks each band past them with a triangle at the edge; whether any was."""
    ax.set_ylim(lo, hi)
    clipped = False
    for xs, ms, hs, colour in drawn:
        for mask, edge, marker in ((ms + hs > hi, hi, "^"), (ms - hs < lo, lo, "v")):
            if mask.any():
                clipped = True
                ax.scatter(xs[mask], np.full(mask.sum(), edge), marker=marker, s=14, color=colour, clip_on=False,
                           zorder=6, edgecolors="white", linewidths=0.4)  # fmt: skip
    return clipped


def clipped_handle():
    return matplotlib.lines.Line2D([], [], linestyle="none", marker="^", color="0.3", markersize=5,
                                   label="CI runs past the axis (clipped)")  # fmt: skip


def seeds_label(rows) -> str:
    counts = sorted({int(r["n_seeds"]) for r in rows})
    text = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    return f"{text} seed" + ("" if text == "1" else "s")


def panel_notes(rows, sep: str = " ") -> tuple[str, str]:
    """(`n seeds, MuJoCo v`, `PPO: older code (rev)`): what a panel's title says of its cells. The
    variants run on another MuJoCo where the others were not are named; so are those whose training
    code (provenance.csv's code and code_date) is older than the newest in the panel ("" if none),
    `sep` before the revision."""
    extra = [seeds_label(rows)]
    other = [r for r in rows if other_mujoco(r)]
    if other:
        versions = f"MuJoCo {', '.join(sorted({r['mujoco'] for r in other}))}"
        if len(other) < len(rows):
            versions = f"{variant_names(other)} on {versions}"
        extra.append(versions)
    newest = max((r.get("code_date", "") for r in rows), default="")
    older = [r for r in rows if r.get("code_date") and r["code_date"] < newest]
    revisions = ", ".join(sorted({r["code"] for r in older}))
    return ", ".join(extra), (f"{variant_names(older, short=True)}: older code{sep}({revisions})" if older else "")


def variant_names(rows, short: bool = False) -> str:
    """The paper's names of the rows' variants, in its order; `short` without "PGG, " (for panel titles)."""
    names = [paper_name(v) for v in sorted({r["variant"] for r in rows}, key=lambda v: (variant_rank(v), v))]
    return ", ".join(name.removeprefix("PGG, ") if short else name for name in names)


def panel_title(env: str, rows) -> str:
    """`env (n seeds, MuJoCo v)`, and on a second line the variants of older training code, if any."""
    extra, code = panel_notes(rows)
    return f"{env} ({extra})" + (f"\n{code}" if code else "")


def variant_colour(variant: str) -> str:
    """The colour of a training variant in every figure (VARIANT_COLOURS; any other by a hash of its name)."""
    if variant in VARIANT_COLOURS:
        return VARIANT_COLOURS[variant]
    return OTHER_VARIANT_COLOURS[zlib.crc32(variant.encode()) % len(OTHER_VARIANT_COLOURS)]


def gamma_marker(gamma: float, kind: str) -> str:
    """The marker of an eval γ in every figure of its table: one per γ of the paper's grid, another for the rest."""
    grid = PAPER_GAMMAS[kind]
    return MARKERS[grid.index(gamma)] if gamma in grid else MARKERS[len(grid)]


def gamma_colour(gamma: float, kind: str) -> str:
    """The colour of an eval γ in every figure of its table: the paper figure's colour for its place in
    that figure's γ set; past the set's largest, the table's other γ in BEYOND_FIGURE_CMAP."""
    shown = PAPER_FIGURE_GAMMAS[kind]
    beyond = [g for g in PAPER_GAMMAS[kind] if g > shown[-1]]
    log_gamma = math.log(max(gamma, 1e-12))
    if beyond and gamma > shown[-1]:
        place = np.interp(log_gamma, np.log(beyond), np.linspace(*BEYOND_FIGURE_SPAN, len(beyond)))
        return matplotlib.colors.to_hex(plt.get_cmap(BEYOND_FIGURE_CMAP)(place))
    place = np.interp(log_gamma, np.log(shown), np.linspace(*GAMMA_CMAP_SPAN, len(shown)))
    return matplotlib.colors.to_hex(plt.get_cmap(GAMMA_CMAP)(place))


def few_seeds(rows) -> bool:
    """Fewer than 3 seeds: with t_{0.975,1} = 12.7 a CI band would dwarf the means."""
    return min(int(r["n_seeds"]) for r in rows) < 3


def dodge(xs, index: int, count: int, spacing: float) -> np.ndarray:
    """Shifts line `index` of `count` sideways by a little, so that stacked lines and their error bars
    stay apart."""
    return np.asarray(xs, dtype=float) + (index - (count - 1) / 2) * 0.25 * spacing / max(count - 1, 1)


def legend_right(fig, entries: list, title: str) -> None:
    """One legend for the figure, right of the panels, in the given order (no duplicates)."""
    seen, handles, labels = set(), [], []
    for _, label, handle in sorted(entries, key=lambda e: e[0]):
        if label not in seen:
            seen.add(label)
            handles.append(handle)
            labels.append(label)
    if handles:
        fig.legend(
            handles,
            labels,
            loc="outside right center",
            fontsize=LEGEND_SIZE,
            frameon=False,
            title=title,
            title_fontsize=LEGEND_SIZE,
        )


def figure_layout(kind: str, envs: list[str]) -> tuple[list[str], int | None]:
    """(panels, columns) of a figure: the tasks swept, never one that was not. Where they are all the
    paper's, in its order, continuous ones three to a row (its 2×3 grid for its six); else as given."""
    paper = PAPER_ENVS.get(kind, ())
    if not all(env in paper for env in envs):
        return list(envs), None
    return [env for env in paper if env in envs], min(3, len(envs)) if kind == "continuous" else None


def figure_for_variant(
    summary,
    envs,
    variant,
    layout: list[str] | None = None,
    cols: int | None = None,
    gammas=None,
    title: str | None = None,
    y_limits: dict | None = None,
):
    """The paper's figure: return against training steps per env; PPO solid black (eval γ=1), one
    dashed line per eval γ of `variant` (those in `gammas`, default all), each in its γ's colour and
    marker and with a small sideways offset. Envs of `layout` without data of `variant` are empty
    panels labelled "not run". `title`: the figure's, where it is not the variant's whole figure.
    `y_limits`: env -> the y-limits of the paper's figure this one stands beside (set_y_range's `fixed`)."""
    layout = layout or list(envs)
    cells = cell_index(summary)
    kind = summary[0]["kind"] if summary else "discrete"
    ppo_series = [s for _, s in ordered_series(summary, "ppo")]
    own_series = [s for _, s in ordered_series(summary, variant)] if variant != "ppo" else ppo_series
    swept = {float(r["eval_guidance"]) for r in summary if r["variant"] == variant}
    gammas = sorted(swept if gammas is None else swept & set(gammas))
    if variant == "ppo":
        gammas = [g for g in gammas if g != 1.0]  # γ = 1 is the black PPO line itself
    styles = ["--", ":", "-.", (0, (5, 1, 1, 1))]
    fig, axes = panels(len(layout), cols)
    entries, any_clipped = [], False
    for ax, env in zip(axes, layout):
        env_rows = [r for r in summary if r["env_id"] == env and r["variant"] in (variant, "ppo")]
        if not any(r["variant"] == variant for r in env_rows):
            not_run(ax, env)
            continue
        steps = sorted({int(r["step"]) for r in env_rows})
        spacing = min(np.diff(steps)) if len(steps) > 1 else steps[0]
        few = few_seeds(env_rows)
        drawn = []
        for i, series in enumerate(ppo_series):
            points = [(s, cells[(env, "ppo", series, s, 1.0)]) for s in steps if (env, "ppo", series, s, 1.0) in cells]
            if points:
                label = series_name("ppo", series) + " (γ = 1)"  # "PPO" alone: the PPO-trained agents
                line, data = plot_series(ax, [p[0] for p in points], [p[1] for p in points], errorbars=not few,
                                         band_alpha=0.06 if few else 0.12, color="black",
                                         linestyle=["-", (0, (1, 1)), "-."][i % 3], marker="o", markersize=3, label=label)  # fmt: skip
                drawn.append(data)
                entries.append(((0, i, 0), label, line))
        for j, series in enumerate(own_series):
            for k, gamma in enumerate(gammas):
                points = [
                    (s, cells[(env, variant, series, s, gamma)])
                    for s in steps
                    if (env, variant, series, s, gamma) in cells
                ]
                if not points:
                    continue
                label = with_series(f"γ = {gamma:g}", series)
                line, data = plot_series(ax, dodge([p[0] for p in points], k, len(gammas), spacing), [p[1] for p in points],
                                         errorbars=not few, band_alpha=0.04 if few else 0.08,
                                         color=gamma_colour(gamma, kind), marker=gamma_marker(gamma, kind),
                                         linestyle=styles[j % len(styles)], markersize=3, linewidth=1.2,
                                         label=label)  # fmt: skip
                drawn.append(data)
                entries.append(((1, j, -gamma), label, line))  # the paper's legend: highest γ first
        any_clipped |= set_y_range(ax, env, drawn, few, fixed=(y_limits or {}).get(env))
        style_axis(ax, panel_title(env, env_rows), "training steps", "return", steps_on_x=True)
    if any_clipped:
        entries.append(((2, 0, 0), clipped_handle().get_label(), clipped_handle()))
    name = paper_name(variant)
    what = (
        "PPO checkpoints evaluated at each guidance γ (not in the paper)"
        if variant == "ppo"
        else f"{name}: evaluated at each guidance γ"
    )
    fig.suptitle(title or what, fontsize=TITLE_SIZE + 1)
    legend_right(fig, entries, "mean ± 95% CI over seeds")
    return fig


def gamma_response(summary, envs, step):
    """Return against eval γ at one step (default: each env's last), one line per variant in its colour
    and marker (several configurations of one variant by line style), the y-axis within the task's
    possible return like every figure (set_y_range)."""
    fig, axes = panels(len(envs))
    entries, any_clipped = [], False
    for ax, env in zip(axes, envs):
        env_rows = [r for r in summary if r["env_id"] == env]
        at = step if step is not None else max(int(r["step"]) for r in env_rows)
        if not any(int(r["step"]) == at for r in env_rows):  # a step another task of the sweep was swept at
            ax.text(0.5, 0.5, f"not swept at {step_label(at)} steps", ha="center", va="center", transform=ax.transAxes,
                    fontsize=9, color="0.45")  # fmt: skip
            style_axis(ax, env, "eval guidance γ (log scale)", "return", steps_on_x=False)
            continue
        few = few_seeds(env_rows)
        drawn = []
        for variant, series in ordered_series(env_rows):
            points = sorted((r for r in env_rows if r["variant"] == variant and r["series"] == series and int(r["step"]) == at),
                            key=lambda r: float(r["eval_guidance"]))  # fmt: skip
            if points:
                label = series_name(variant, series)
                style = LINE_STYLES[
                    [s for v, s in ordered_series(env_rows) if v == variant].index(series) % len(LINE_STYLES)
                ]
                line, data = plot_series(ax, [float(r["eval_guidance"]) for r in points], points, errorbars=not few,
                                         band_alpha=0.06 if few else 0.12, marker=MARKERS[variant_rank(variant)],
                                         markersize=3, color=variant_colour(variant), linestyle=style,
                                         label=label)  # fmt: skip
                drawn.append(data)
                entries.append(((variant_rank(variant), variant, series), label, line))
        ax.set_xscale("log")
        # Ticks at the swept γ only: over 1–1.5 a log axis otherwise labels its minor ticks in ×10⁰ form.
        swept = sorted({float(r["eval_guidance"]) for r in env_rows})
        ax.set_xticks(swept, labels=[f"{g:g}" for g in swept])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        if len(swept) > 6:
            plt.setp(ax.get_xticklabels(), rotation=45)
        any_clipped |= set_y_range(ax, env, drawn, few)
        extra, code = panel_notes([r for r in env_rows if int(r["step"]) == at], sep="\n")
        title = f"{env} at {step_label(at)} steps\n{extra}" + (f"\n{code}" if code else "")
        style_axis(ax, title, "eval guidance γ (log scale)", "return", steps_on_x=False)
    if any_clipped:
        entries.append(((9, "", ""), clipped_handle().get_label(), clipped_handle()))
    legend_right(fig, entries, "trained as (each evaluated\nat the γ on the x-axis)")
    return fig


def learning_curves(curves: dict, left_out=(), bins: int = 50, min_points: int = 5) -> matplotlib.figure.Figure:
    """Episodic training return against steps, one panel per env, from `curves` ({(env, variant,
    configuration label): [(steps, returns) per seed]}, plot_results.training_curves): per variant and
    configuration the mean over seeds of each seed's mean in each of `bins` step bins, with the t 95% CI.
    Draws whatever points exist and says so in the panel when they are too few for a curve. `left_out`:
    (env, run directory, why) of each run not drawn, named in its env's panel."""
    envs = sorted({env for env, _, _ in curves} | {env for env, _, _ in left_out})
    fig, axes = panels(len(envs))
    for ax, env in zip(axes, envs):
        skipped = [f"{Path(run_dir).name}: {why}" for e, run_dir, why in left_out if e == env]
        if skipped:
            ax.text(0.02, 0.98, "left out, not whole:\n" + "\n".join(skipped), transform=ax.transAxes, fontsize=5,
                    va="top", color="firebrick", wrap=True)  # fmt: skip
        if not any(e == env for e, _, _ in curves):
            style_axis(ax, env, "training steps", "episodic return", steps_on_x=True)
            continue
        drawn, notes = [], []
        of_env = [((v, label), seeds) for (e, v, label), seeds in curves.items() if e == env]
        for (variant, label), seeds in sorted(of_env, key=lambda kv: (variant_rank(kv[0][0]), kv[0])):
            style = LINE_STYLES[[lb for (v, lb), _ in of_env if v == variant].index(label) % len(LINE_STYLES)]
            edges = np.linspace(0, max(s.max() for s, _ in seeds) + 1, bins + 1)
            per_seed = np.array([[r[(s >= lo) & (s < hi)].mean() if ((s >= lo) & (s < hi)).any() else np.nan
                                  for lo, hi in itertools.pairwise(edges)] for s, r in seeds])  # fmt: skip
            centres = (edges[:-1] + edges[1:]) / 2
            present = ~np.isnan(per_seed).all(axis=0)
            stats_per_bin = [mean_ci95(col[~np.isnan(col)]) for col in per_seed.T[present]]
            banded = len(seeds) >= 3  # with 2 seeds t_{0.975,1} = 12.7: a band would cover the panel
            rows = [{"mean": m, "ci95": h if banded else 0.0} for m, h, _, _ in stats_per_bin]
            name = series_name(variant, label) + f" (n={len(seeds)}{'' if banded else ', no CI band'})"
            few = present.sum() < min_points
            _, data = plot_series(ax, centres[present], rows, errorbars=False, band_alpha=0.1 if len(seeds) > 2 else 0.05,
                                  color=variant_colour(variant), linestyle=style, linewidth=1,
                                  marker="o" if few else None, markersize=3, label=name)  # fmt: skip
            drawn.append(data)
            if few:
                count = int(present.sum())
                notes.append(f"{series_name(variant, label)}: only {count} point{'' if count == 1 else 's'}")
        clipped = set_y_range(
            ax, env, drawn, few=min(len(seeds) for (e, _, _), seeds in curves.items() if e == env) < 3
        )
        style_axis(ax, env, "training steps", "episodic return", steps_on_x=True)
        handles, labels = ax.get_legend_handles_labels()
        if clipped:
            handles.append(clipped_handle())
            labels.append("CI clipped")
        ax.legend(handles, labels, fontsize=LEGEND_SIZE - 2, frameon=False)
        if notes:
            ax.text(0.02, 0.02, "too few points for a curve:\n" + "\n".join(notes), transform=ax.transAxes, fontsize=6,
                    va="bottom", color="0.3")  # fmt: skip
    return fig


PAPER_REFERENCE_TEXT = "0 = the paper's PPO at its first step, 1 = at its last"


def aggregate_intervals(aggregate: list[dict], kind: str, reference: str = PAPER_REFERENCE_TEXT):
    """The aggregate IQM as rliable draws it: at the last step, one row per (variant, eval γ), the IQM
    of normalised scores with its 95% CI as a bar, in the variant's colour; dotted lines at the two
    fixed references, which `reference` names (paper_study.aggregate.reference_text: the paper's PPO at its first
    step and at its last, or the sweep's own). `aggregate`: aggregate_iqm's rows."""
    last = max(int(r["step"]) for r in aggregate)
    rows = sorted((r for r in aggregate if int(r["step"]) == last),
                  key=lambda r: (variant_rank(r["variant"]), r["variant"], -float(r["eval_guidance"])))  # fmt: skip
    fig, ax = plt.subplots(figsize=(6.0, 0.75 + 0.28 * len(rows)), layout="constrained")
    for y, r in enumerate(reversed(rows)):
        colour = variant_colour(r["variant"].split(" [")[0])
        low, high = float(r["ci_low"]), float(r["ci_high"])
        if not math.isnan(low):
            ax.barh(y, high - low, left=low, height=0.6, color=colour, alpha=0.35, linewidth=0)
        ax.plot([float(r["iqm"])], [y], marker="|", markersize=12, color=colour, markeredgewidth=2)
    ax.set_yticks(range(len(rows)),
                  labels=[f"{series_label(r['variant'])}, γ = {float(r['eval_guidance']):g}" for r in reversed(rows)])  # fmt: skip
    for x in (0.0, 1.0):
        ax.axvline(x, color="0.5", linestyle=":", linewidth=1)
    envs = int(rows[0]["n_envs"]) if rows else 0
    style_axis(ax, f"{kind.capitalize()}: IQM over {envs} tasks × seeds at {step_label(last)} steps (95% CI)",
               f"normalised score: {reference}", "", steps_on_x=False)  # fmt: skip
    ax.grid(axis="y", visible=False)
    return fig


def performance_profiles(profiles: dict, step: int, envs: int, kind: str, reference: str = PAPER_REFERENCE_TEXT):
    """rliable's performance profile beside the aggregate IQM, from the same normalised scores: one
    panel per variant, one line per eval γ (its colour in every figure) of the fraction of (task, seed)
    scores above each τ, its stratified-bootstrap 95% CI as a band, over the τ the scores span; dotted
    lines at the two fixed references, which `reference` names, where they lie in that span.
    `profiles`: {(variant [series], eval γ): (taus, profile, low, high)} (paper_study.aggregate.performance_profiles)."""
    variants = sorted({v for v, _ in profiles}, key=lambda v: (variant_rank(v.split(" [")[0]), v))
    fig, axes = panels(len(variants))
    entries = []
    for ax, variant in zip(axes, variants, strict=True):
        for gamma in sorted(g for v, g in profiles if v == variant):
            taus, profile, low, high = profiles[(variant, gamma)]
            colour = gamma_colour(gamma, kind)
            (line,) = ax.plot(taus, profile, color=colour, linewidth=1.2, drawstyle="steps-post")
            ax.fill_between(taus, low, high, color=colour, alpha=0.15, linewidth=0, step="post")
            entries.append((gamma, f"γ = {gamma:g}", line))
        for x in (0.0, 1.0):
            ax.axvline(x, color="0.5", linestyle=":", linewidth=1)
        ax.set_xlim(taus[0], taus[-1])
        ax.set_ylim(-0.02, 1.02)
        style_axis(ax, series_label(variant), "normalised score τ", "fraction of runs with score > τ", steps_on_x=False)
    legend_right(fig, entries, "eval γ")
    fig.suptitle(f"{kind.capitalize()}: performance profile over {envs} tasks × seeds at {step_label(step)} steps "
                 f"(95% CI; {reference})", fontsize=TITLE_SIZE)  # fmt: skip
    return fig


def series_label(series: str) -> str:
    """The paper's name of an aggregate row's variant (`variant [series]`)."""
    variant, _, rest = series.partition(" [")
    return paper_name(variant) + (f" [{rest}" if rest else "")
