"""The one reader of a sweep's episodes.csv, for plot_results and the paper study: every row checked
(its columns, a finite number where one belongs, a return its task allows), the file checked whole
against its sweep's record (files.check_record) or, without one, cell by cell, and runs never pooled
(check_one_run_per_seed). The per-seed means its readers start from are seed_means,
which the sweep's own summary uses too. Plain Python: nothing of the paper study. Pooling over seeds is here too: within one configuration a seed is one run and each episode of a cell counts once (check_one_run_per_seed); every statistic over seeds starts from the per-seed means (seed_means), then the mean and its 95% confidence interval (mean_ci95), the two per group of rows in summarise, which summary.csv and the tables both start from."""

import functools
import json
import math
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

from pgg_utils.files import InputError, check_record, read_csv_columns
from pgg_utils.identity import configuration, label_of

FILE_NAME = "episodes.csv"
REQUIRED_COLUMNS = {"env_id", "variant", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy",
                    "null_branch", "seed", "return"}  # fmt: skip
NUMBER_COLUMNS = ("return", "train_guidance", "cond_dropout", "eval_guidance")
INTEGER_COLUMNS = ("step", "seed")
# The possible return of a task, where it has one: a return outside it is an edited file (and figures'
# axes never extend past it).
RETURN_RANGE = {"CartPole-v1": (0.0, 500.0), "Acrobot-v1": (-500.0, 0.0), "InvertedPendulum-v4": (0.0, 1000.0),
                "InvertedPendulum-v5": (0.0, 1000.0)}  # fmt: skip


def episodes_csv(raw) -> Path:
    """A sweep's episodes.csv, given the file or the sweep's folder."""
    path = Path(raw)
    return path / FILE_NAME if path.is_dir() else path


def read_episodes(paths, check=None) -> list[dict]:
    """Every episode row of the given sweeps (files or folders), each with its `config` (the variant
    where the CSV has no such column) and `_source` (the CSV it came from). InputError with one line for
    a file that is missing, empty or no sweep's, a value no sweep writes, a file that differs from its
    sweep's record or (without one) holds a cell with fewer episodes than its other cells, and for two
    runs that would count as one seed of a configuration or one episode counted twice. `check(rows)`: a
    reader's own check of every row read (e.g. the tables' action space), before runs are compared."""
    rows = []
    for raw in paths:
        path = episodes_csv(raw)
        if not path.exists():
            raise InputError(f"no sweep CSV at {path}")
        columns, of_file = read_csv_columns(path)
        if columns is None:
            raise InputError(f"{path} is empty")
        missing = REQUIRED_COLUMNS - set(columns)
        if missing:
            raise InputError(f"{path} lacks columns {sorted(missing)}; is it an episodes.csv of eval_gamma_sweep.py?")
        check_record(path, len(of_file))
        for line, row in enumerate(of_file, start=2):
            check_values(row, f"{path}, line {line}")
            row["config"] = row.get("config") or row["variant"]
            row["_source"] = str(path)
        check_whole_cells(of_file, path)
        rows.extend(of_file)
    if check is not None:
        check(rows)
    check_one_run_per_seed(rows, configuration, cell_of, source=lambda row: row["_source"])
    return rows


def check_values(row: dict, where: str) -> None:
    """InputError with one line for a value no sweep writes (an edited episodes.csv): a number column
    that is not a finite number, a step or seed that is not an integer, a return outside what its task
    allows (RETURN_RANGE), a `config_fields` that does not spell its `config` label."""
    for column in (*NUMBER_COLUMNS, *INTEGER_COLUMNS):
        value = row[column]
        try:
            number = int(value) if column in INTEGER_COLUMNS else float(value)
        except (TypeError, ValueError):
            raise InputError(
                f"{where}: {column} {value!r} is not a{'n integer' if column in INTEGER_COLUMNS else ' number'}"
            ) from None
        if not math.isfinite(number):
            raise InputError(f"{where}: {column} {value!r} is not finite")
    if row.get("config_fields") and not fields_spell_label(row["variant"], row.get("config"), row["config_fields"]):
        raise InputError(f"{where}: config_fields {row['config_fields']!r} is not the JSON object of its "
                         f"config {row.get('config')!r}")  # fmt: skip
    low, high = RETURN_RANGE.get(row["env_id"], (-math.inf, math.inf))
    if not low <= float(row["return"]) <= high:
        raise InputError(f"{where}: return {row['return']} is outside what {row['env_id']} allows, [{low:g}, {high:g}]")


@functools.cache
def fields_spell_label(variant: str, config: str | None, encoded: str) -> bool:
    """Whether `encoded` is a JSON object whose fields, after `variant`, spell the label `config` (identity.label_of)."""
    try:
        fields = json.loads(encoded)
    except ValueError:
        return False
    return isinstance(fields, dict) and label_of(variant, fields) == config


def check_whole_cells(rows: list[dict], path: Path) -> None:
    """A sweep evaluates every cell of one CSV (run, step, γ, evaluation mode) for the same number of
    episodes: InputError where a cell holds fewer than the others, the mark of a cut or edited file."""
    counts = defaultdict(int)
    for row in rows:
        counts[(*configuration(row), row["seed"], *cell_of(row))] += 1
    most = max(counts.values(), default=0)
    short = {cell: n for cell, n in counts.items() if n < most}
    if short:
        (env, _, config, _, _, seed, step, gamma, *_), n = next(iter(short.items()))
        raise InputError(f"{path}: {len(short)} cell(s) hold fewer episodes than the other cells' {most}, e.g. {env} "
                         f"{config} seed {seed} at step {step}, eval γ {gamma}: {n} (a cut or edited file); rerun the "
                         "sweep to write it whole")  # fmt: skip


def select_mode(rows: list[dict], policy: str, null_branch: str) -> list[dict]:
    """The rows of one evaluation mode; InputError where there are none."""
    selected = [r for r in rows if r["policy"] == policy and r["null_branch"] == null_branch]
    if not selected:
        raise InputError(f"no episodes with policy={policy} and null_branch={null_branch}")
    return selected


def cell_of(row: dict) -> tuple:
    """(step, γ, evaluation mode) of a sweep's row: which cell of its run it belongs to."""
    return (row["step"], row["eval_guidance"], row["policy"], row["null_branch"])


def check_one_run_per_seed(rows, configuration, cell, source=lambda row: None) -> None:
    """InputError (one line) where two runs would count as the same seed of one configuration
    (`configuration(row)`: env, variant, config, ...), or one episode of a cell (`cell(row)`: step, γ,
    evaluation mode) appears twice. An episode is its reset seed where the row records one (`episode_seed`):
    two sweeps of one checkpoint with other --eval-seed values hold other episodes, pooled as one sweep's
    would be, while an episode index alone repeats in every sweep. `source(row)` names where a row was read
    from, for the message."""
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
        reset_seed = str(row.get("episode_seed") or "")
        episode = (key, seed, run, *cell(row), reset_seed or str(row["episode"]))
        if episode in seen:
            first = seen[episode]
            twice = (
                "twice" if first is None else f"in {first} twice" if first == where else f"in both {first} and {where}"
            )
            which = f"episode {row['episode']}" + (f" (reset seed {reset_seed})" if reset_seed else "")
            raise InputError(f"{which} of run {run} ({' '.join(map(str, cell(row)))}) appears {twice}: one episode "
                             "counted twice; pass each sweep once")  # fmt: skip
        seen[episode] = where


def mean_ci95(values, method: str = "t", bootstrap_samples: int = 10_000) -> tuple[float, float, float, float]:
    """(mean, half-width, low, high) of the 95% confidence interval of the mean of `values` (here:
    one mean return per training seed). "t": mean ± t_{0.975, n-1} · s / sqrt(n), s the sample standard
    deviation (ddof=1). "bootstrap": percentile interval of `bootstrap_samples` resampled means (fixed
    RNG seed), half-width = (high - low) / 2. With one value the interval is undefined (nan)."""
    values = np.asarray(values, dtype=np.float64)
    n, mean = len(values), float(np.mean(values))
    if n < 2:
        return mean, math.nan, math.nan, math.nan
    if method == "t":
        half = float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n))
        return mean, half, mean - half, mean + half
    resampled = np.random.default_rng(0).choice(values, size=(bootstrap_samples, n)).mean(1)
    low, high = np.percentile(resampled, [2.5, 97.5])
    return mean, float((high - low) / 2), float(low), float(high)


def seed_means(rows, key, value: str = "return") -> dict:
    """{key(row): {seed: mean return over that seed's episodes}}, seeds in numeric order: the per-seed
    mean that every statistic over seeds starts from (the sweep's summary, the tables, the paper study).
    The returns of a seed are summed in row order. `value`: the per-episode column averaged, the return unless
    a reader averages another (a goal distance's `final_distance`)."""
    returns = defaultdict(lambda: defaultdict(list))
    for row in rows:
        returns[key(row)][int(row["seed"])].append(float(row[value]))
    return {k: {seed: float(np.mean(v)) for seed, v in sorted(by_seed.items())} for k, by_seed in returns.items()}


def summarise(rows, key, order=None, method: str = "t", bootstrap_samples: int = 10_000) -> list[dict]:
    """Statistics over seeds of the per-seed mean return, one entry per group `key(row)`, sorted by `order(group)`:
    {"key": the group, "seeds": its seeds in numeric order, "seed_means": their mean returns (seed_means),
    "n_episodes": its rows, "mean", "ci95", "ci_low", "ci_high": mean_ci95 of the seed means (`method`)}, unrounded.
    The one summary over seeds: the sweep's summary.csv (pgg_utils.sweep.summary_rows) and the paper study's
    tables (paper_study.summary.summarise) add their columns to it."""
    per_seed, episodes = seed_means(rows, key), Counter(map(key, rows))
    out = []
    for group in sorted(per_seed, key=order):
        means = list(per_seed[group].values())
        mean, half, low, high = mean_ci95(means, method, bootstrap_samples)
        out.append({"key": group, "seeds": list(per_seed[group]), "seed_means": means, "n_episodes": episodes[group],
                    "mean": mean, "ci95": half, "ci_low": low, "ci_high": high})  # fmt: skip
    return out
