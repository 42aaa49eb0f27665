"""The rule behind every statistic over seeds, once: within one configuration a seed is one run, and
each episode of a cell is counted once."""

from pgg_utils.files import InputError


def cell_of(row: dict) -> tuple:
    """(step, γ, evaluation mode) of a sweep's row: which cell of its run it belongs to."""
    return (row["step"], row["eval_guidance"], row["policy"], row["null_branch"])


def check_one_run_per_seed(rows, configuration, cell, source=lambda row: None) -> None:
    """InputError (one line) where two runs would count as the same seed of one configuration
    (`configuration(row)`: env, variant, config, ...), or one episode of a cell (`cell(row)`: step, γ,
    evaluation mode) appears twice. `source(row)` names where a row was read from, for the message."""
    run_of, seen = {}, {}
    for row in rows:
        key, seed, run, where = configuration(row), str(row["seed"]), str(row.get("run", "")), source(row)
        first_run, first_where = run_of.setdefault((key, seed), (run, where))
        if first_run != run:
            runs = f"{first_run}{f' ({first_where})' if first_where else ''} and {run}{f' ({where})' if where else ''}"
            raise InputError(f"runs {runs} would both count as seed {seed} of {' '.join(map(str, key[:3]))}: a seed "
                             "must be one run (give them different configurations, or sweep and plot them apart)")  # fmt: skip
        if "episode" not in row:
            continue
        episode = (key, seed, run, *cell(row), str(row["episode"]))
        if episode in seen:
            first = seen[episode]
            twice = (
                "twice" if first is None else f"in {first} twice" if first == where else f"in both {first} and {where}"
            )
            raise InputError(f"episode {row['episode']} of run {run} ({' '.join(map(str, cell(row)))}) appears {twice}: "
                             "pass each sweep once")  # fmt: skip
        seen[episode] = where
