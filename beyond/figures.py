"""The report's figures: the γ-response per task, the schedules' γ_train, the distance to the goal, the
behaviour-cloned nulls' γ-response, the command task's tracking and the condition-dropout sets'."""

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from beyond.cells import cells_of, last_step
from beyond.command import per_seed, read_tracking
from beyond.condition_dropout import drawn
from beyond.dropout_command import command_bands
from beyond.dropout_sets import Sets
from beyond.fitted_null import null_name
from beyond.schedules import scheduled_tasks
from beyond.sets import BC, COMMAND_FOLDER, COMMAND_SET, COMMAND_VARIANTS, GOAL_ENV, GOAL_SET
from beyond.text import name
from paper_study.agreement import step_label
from paper_study.figures import steps_formatter, variant_colour
from paper_study.paper import paper_name
from pgg_utils.episodes import mean_ci95


def band(ax, xs, per_x_values, variant: str, label: str | None = None, linestyle: str = "-") -> None:
    """A variant's mean over seeds against x, with its 95% CI as a band."""
    stats = [mean_ci95(values) for values in per_x_values]
    mean, half = np.array([s[0] for s in stats]), np.array([s[1] for s in stats])
    color = variant_colour(variant)
    ax.plot(xs, mean, marker="o", ms=3, color=color, label=label or paper_name(variant), linestyle=linestyle)
    ax.fill_between(xs, mean - half, mean + half, color=color, alpha=0.15)


def panels(count: int, height: float, columns: int = 3):
    """`count` panels, `columns` to a row; the unused ones of the last row are hidden."""
    rows, columns = -(-count // columns), min(count, columns)
    fig, grid = plt.subplots(rows, columns, figsize=(4.3 * columns, height * rows), squeeze=False)
    axes = list(grid.flat)
    for ax in axes[count:]:
        ax.set_visible(False)
    return fig, axes[:count]


def save(fig, axes, path: Path) -> None:
    for ax in axes:  # each panel names its own variants: tasks differ in which were run
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def gamma_response_figure(means: dict, envs: list[str], variants_of: dict, path: Path) -> None:
    """A panel per task: the tasks of the schedules first (a row of their own for the paper's three), then the goal's."""
    envs = [*scheduled_tasks(variants_of), *(e for e in envs if e not in scheduled_tasks(variants_of))]
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        last = last_step(means, env)
        for variant in variants_of[env]:
            cells = cells_of(means, env, variant)
            gammas = sorted(g for (s, g) in cells if s == last)
            band(ax, gammas, [list(cells[(last, g)].values()) for g in gammas], variant)
        ax.set(title=f"{env}, {step_label(last)}", xlabel="eval guidance γ", ylabel="return")
    save(fig, axes, path)


def trajectory_figure(trajectories: dict, path: Path) -> None:
    keys = sorted(trajectories)
    fig, axes = panels(len(keys), 3.2, columns=len({v for e, v in keys}))  # a row per task
    for ax, (env, variant) in zip(axes, keys):
        for seed, points in sorted(trajectories[(env, variant)].items()):
            steps, gammas, _ = zip(*sorted(points))
            ax.plot(steps, gammas, color=variant_colour(variant), alpha=0.7, lw=1, label=f"seed {seed}")
        ax.set_title(f"{env}\n{paper_name(variant)}", fontsize=9)
        ax.set(xlabel="training steps", ylabel="γ_train")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(steps_formatter))
    save(fig, axes, path)


def distance_figure(distance: dict, variants_of: dict, path: Path) -> None:
    """A panel per goal task, of the variants the report's tables hold (goal_distance.csv may hold more)."""
    envs = sorted({e for (e, v, g) in distance if e in variants_of})
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        for variant in (v for v in variants_of[env] if (env, v, 1.0) in distance):
            gammas = sorted(g for (e, v, g) in distance if e == env and v == variant)
            band(ax, gammas, [list(distance[(env, variant, g)].values()) for g in gammas], variant)
        ax.set_title(f"{env}: final distance to the goal", fontsize=10)
        ax.set(xlabel="eval guidance γ", ylabel="distance (lower is closer)")
    save(fig, axes, path)


def bc_figure(means: dict, sets: list[tuple[str, str]], path: Path) -> None:
    """A panel per task: each set of agents' γ-response with its own null (solid) and the cloned one (dashed)."""
    envs = list(dict.fromkeys(env for env, _ in sets))
    fig, axes = panels(len(envs), 3.4)
    for ax, env in zip(axes, envs):
        for variant in (v for e, v in sets if e == env):
            for key, style in ((variant, "-"), (variant + BC, "--")):
                cells, last = cells_of(means, env, key), last_step(means, env)
                gammas = sorted(g for (s, g) in cells if s == last)
                band(ax, gammas, [list(cells[(last, g)].values()) for g in gammas], variant,
                     f"{paper_name(variant)}, {null_name(key)} null", style)  # fmt: skip
        ax.set(title=f"{env}, {step_label(last_step(means, env))}", xlabel="eval guidance γ", ylabel="return")
        ax.set_xscale("log" if max(g for (e, v, s, g) in means if e == env) > 2 else "linear")
    save(fig, axes, path)


def command_figure(folder: Path, path: Path) -> bool:
    """Commanded against achieved velocity, one line per eval γ, a panel per variant; False where no tracking."""
    tracking_csv = folder / COMMAND_FOLDER / "tracking.csv"
    if not tracking_csv.exists():
        return False
    cells, inside, last = read_tracking(tracking_csv)
    if not cells:
        return False
    variants = [v for v in COMMAND_VARIANTS if any(k[0] == v for k in cells)]
    gammas, commands = sorted({g for (v, s, g, c) in cells}), sorted({c for (v, s, g, c) in cells})
    in_range = [c for c in commands if inside[c]]
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(gammas)))
    fig, axes = panels(len(variants), 3.6)
    for ax, variant in zip(axes, variants):
        if in_range:
            ax.axvspan(min(in_range), max(in_range), color="0.9", zorder=0)
        ax.plot(commands, commands, color="0.4", linestyle="--", lw=1)
        for gamma, colour in zip(gammas, colours):
            shown = [c for c in commands if per_seed(cells, variant, gamma, [c], "velocity")]
            stats = [mean_ci95(list(per_seed(cells, variant, gamma, [c], "velocity").values())) for c in shown]
            mean, half = np.array([s[0] for s in stats]), np.array([s[1] for s in stats])
            ax.plot(shown, mean, marker="o", ms=3, color=colour, label=f"γ = {gamma:g}")
            ax.fill_between(shown, mean - half, mean + half, color=colour, alpha=0.12)
        ax.set(title=f"{paper_name(variant)}\n({COMMAND_VARIANTS[variant]}), {step_label(last)}",
               xlabel="commanded velocity (m/s)", ylabel="achieved mean velocity (m/s)")  # fmt: skip
        ax.title.set_fontsize(9)
    save(fig, axes, path)
    return True


def dropout_figure(sets: Sets, path: Path) -> bool:
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
