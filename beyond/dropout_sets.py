"""What the condition-dropout section reads (Sets): the command task's tracking cells, Reacher-v4's final
distances and the learned nulls' rows of the dropout sets and of the sets beside them; a line per file absent."""

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from beyond.command import read_tracking
from beyond.sets import COMMAND_DROPOUT, COMMAND_FOLDER, COMMAND_SET, DROPOUT_FOLDER, GOAL_DROPOUT, GOAL_ENV, GOAL_SET
from pgg_utils.episodes import seed_means
from pgg_utils.files import read_csv

LEARNED_NULL = "learned_null.csv"


@dataclass
class Sets:
    """What the section reads: the command task's cells {(variant, seed, γ, command): {field: mean over episodes,
    "episodes": n}} at each file's last step, {command: inside the training range}, {variant: step}; Reacher's
    {(variant, γ): {seed: (mean final distance, episodes)}} and {variant: step}; the learned nulls' rows; and a
    line per file absent."""

    command: dict = field(default_factory=dict)
    inside: dict = field(default_factory=dict)
    command_steps: dict = field(default_factory=dict)
    goal: dict = field(default_factory=dict)
    goal_steps: dict = field(default_factory=dict)
    nulls: list = field(default_factory=list)
    absent: dict = field(default_factory=dict)


def read_tracking_into(sets: Sets, path: Path, variants) -> None:
    """The cells of `variants` in one tracking.csv at its last step, into `sets`."""
    cells, inside, last = read_tracking(path, variants)
    sets.inside.update(inside)
    sets.command.update(cells)
    sets.command_steps.update(dict.fromkeys((key[0] for key in cells), last))


def read_goal_into(sets: Sets, path: Path, variants) -> None:
    """Reacher's final distances of `variants` in one goal_distance.csv at each variant's last step, into `sets`."""
    rows = [r for r in read_csv(path) if r["env_id"] == GOAL_ENV and r["variant"] in variants]
    last = {}
    for r in rows:
        last[r["variant"]] = max(last.get(r["variant"], 0), int(r["step"]))
    rows = [r for r in rows if int(r["step"]) == last[r["variant"]]]
    key = lambda r: (r["variant"], float(r["eval_guidance"]))
    episodes = Counter((key(r), int(r["seed"])) for r in rows)
    for cell, by_seed in seed_means(rows, key, value="final_distance").items():
        sets.goal[cell] = {seed: (mean, episodes[(cell, seed)]) for seed, mean in by_seed.items()}
    sets.goal_steps.update(last)


def read(folder: Path) -> Sets:
    """Every file the section reads, from `folder` (results/beyond); the absent ones named."""
    sets, dropout = Sets(), folder / DROPOUT_FOLDER
    sources = (
        ("command", dropout / COMMAND_FOLDER / "tracking.csv", {COMMAND_DROPOUT}, read_tracking_into),
        ("command baselines", folder / COMMAND_FOLDER / "tracking.csv", set(COMMAND_SET) - {COMMAND_DROPOUT},
         read_tracking_into),
        ("goal", dropout / "goal_distance.csv", {GOAL_DROPOUT}, read_goal_into),
        ("goal baselines", folder / "goal_distance.csv", set(GOAL_SET) - {GOAL_DROPOUT}, read_goal_into),
    )  # fmt: skip
    for name, path, variants, reader in sources:
        if path.exists():
            reader(sets, path, variants)
        else:
            sets.absent[name] = path.relative_to(folder)
    for path in (folder / COMMAND_FOLDER, folder / GOAL_ENV, dropout / COMMAND_FOLDER, dropout / GOAL_ENV):
        if (path / LEARNED_NULL).exists():
            sets.nulls += read_csv(path / LEARNED_NULL)
    return sets
