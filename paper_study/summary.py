"""The tables' summary of a sweep's episodes: one row per configuration, checkpoint step, eval γ and
evaluation mode, with the statistics over seeds of the per-seed mean return (pgg_utils.episodes), the
label that tells configurations of one task and variant apart, its table (discrete or continuous) and
the MuJoCo version and code revision behind it. plot_results.py writes its tables and figures from
these rows; compare_sweeps, heldout_gamma and the dropout figure's reader use the same. Its rows are read by
pgg_utils.episodes.read_episodes, the one reader, and its statistics are pgg_utils.episodes.summarise's, the one
summary over seeds."""

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from paper_study.agreement import series_id
from paper_study.paper import action_kind, variant_rank
from pgg_utils.episodes import summarise as summarise_seeds
from pgg_utils.files import InputError, read_csv
from pgg_utils.identity import config_fields, configuration, is_mujoco

ROOT = Path(__file__).resolve().parent.parent
KINDS = ("discrete", "continuous")  # the paper's two tables, by action space


def table_kinds(rows: list[dict]) -> dict:
    """{env: the table it belongs to, discrete or continuous} of the episode rows (kind_of); InputError where the
    CSVs disagree on an env's. The tables' readers pass it as pgg_utils.episodes.read_episodes's `check`, so that a
    disagreement is said before anything else of the rows."""
    first = {}  # env -> (kind, source)
    for row in rows:
        kind = kind_of(row, Path(row["_source"]))
        first_kind, source = first.setdefault(row["env_id"], (kind, row["_source"]))
        if kind != first_kind:
            raise InputError(
                f"{row['env_id']} has {first_kind} actions in {source} and {kind} actions in {row['_source']}"
            )
    return {env: kind for env, (kind, _) in first.items()}


def kind_of(row: dict, path: Path) -> str:
    """The table a row belongs to, discrete or continuous: the action space its sweep recorded, else
    the task's own (paper_study.paper.action_kind), never a guess from the env's name."""
    recorded = row.get("action_space")
    if recorded:
        if recorded not in KINDS:
            raise InputError(f"{path}: action_space {recorded!r} of {row['env_id']} is neither discrete nor continuous")
        return recorded
    try:
        return action_kind(row["env_id"])
    except ValueError as e:
        raise InputError(f"{path} records no action_space for {row['env_id']}, and {e}") from None


def config_labels(configs: dict) -> dict:
    """{(env, variant, config, guidance, dropout): (its label's fields, its source set)} -> the label that
    tells configurations of one env and variant apart: the fields whose values differ (`key=default` where a
    config does not set one; guidance and dropout exactly), with the source folder added where that is still
    ambiguous; none where the env and variant have one configuration. A fork's script (`script`) is named wherever
    it trained, alone or beside others: its numbers are never the original's."""
    groups = defaultdict(dict)
    for (env, variant, *config), entry in configs.items():
        groups[(env, variant)][tuple(config)] = entry
    labels = {}
    for (env, variant), found in groups.items():
        tokens = {c: fields | {"guidance": repr(c[1]), "cond_dropout": repr(c[2])} for c, (fields, _) in found.items()}
        keys = sorted({k for t in tokens.values() for k in t})
        differing = [k for k in keys if len({t.get(k) for t in tokens.values()}) > 1]
        named = {c: " ".join(f"{k}={tokens[c].get(k, 'default')}" for k in keys if k in differing
                             or (k == "script" and k in tokens[c])) for c in found}  # fmt: skip
        if len(found) == 1:
            labels.update({(env, variant, *c): named[c] for c in found})
            continue
        for c, (_, sources) in found.items():
            if not named[c] or list(named.values()).count(named[c]) > 1:
                folders = sorted({Path(s).parent.name or s for s in sources})
                named[c] = " ".join(filter(None, [named[c], f"from {', '.join(folders)}"]))
            labels[(env, variant, *c)] = named[c]
    return labels


def summarise(rows: list[dict], provenance: dict | None = None) -> list[dict]:
    """The tables' summary of episode rows (pgg_utils.episodes.read_episodes): pgg_utils.episodes.summarise per
    (configuration, step, γ, policy, null branch), each with the configuration's label (`series`), its table
    (`kind`), MuJoCo version and code revision, its seeds' standard deviation, and how many seeds its siblings hold."""
    sources, fields = defaultdict(set), {}
    for row in rows:
        sources[configuration(row)].add(row["_source"])
        fields.setdefault(configuration(row), config_fields(row))
    kinds, labels = table_kinds(rows), config_labels({c: (fields[c], s) for c, s in sources.items()})
    out = []
    for cell in summarise_seeds(rows, cell_key, lambda k: (k[0], variant_rank(k[1]), *k[1:])):
        key, means = cell["key"], cell["seed_means"]
        env, variant, config, guidance, dropout, step, gamma, policy, null_branch = key
        out.append({
            "env_id": env, "variant": variant, "config": config, "train_guidance": guidance, "cond_dropout": dropout,
            "config_fields": fields[key[:5]], "kind": kinds[env], "series": labels[key[:5]],
            "step": step, "eval_guidance": gamma, "policy": policy, "null_branch": null_branch,
            "n_seeds": len(means), "n_episodes": cell["n_episodes"],
            "mean": cell["mean"], "ci95": cell["ci95"], "sd": float(np.std(means, ddof=1)) if len(means) > 1 else math.nan,
            "seed_means": ";".join(f"{m:.4f}" for m in means), "seeds": cell["seeds"],
            "mujoco": mujoco_of(env, fields[key[:5]], sources[key[:5]], provenance), "sources": sorted(sources[key[:5]]),
            **code_of(sources[key[:5]], provenance),
        })  # fmt: skip
    # A cell's siblings are the other cells of its configuration and evaluation mode: a run missing from
    # one (a cut file, a run stopped before its last checkpoint) leaves it with fewer seeds, which it says.
    # A seed missing from every cell of a configuration leaves no sibling with more: the configuration then
    # says so against the other configurations of its task evaluated the same way.
    most, most_of_task = defaultdict(int), defaultdict(int)
    for r in out:
        most[sibling_key(r)] = max(most[sibling_key(r)], r["n_seeds"])
        most_of_task[task_key(r)] = max(most_of_task[task_key(r)], r["n_seeds"])
    for r in out:
        r["config_seeds"] = most[sibling_key(r)]
        r["of_seeds"] = most_of_task[task_key(r)]
    return out


def cell_key(row: dict) -> tuple:
    """A summary cell of an episode row: its configuration, step, eval γ and evaluation mode."""
    return (*configuration(row), int(row["step"]), float(row["eval_guidance"]), row["policy"], row["null_branch"])


def sibling_key(row: dict) -> tuple:
    return (row["env_id"], row["variant"], row["config"], row["train_guidance"], row["cond_dropout"], row["policy"],
            row["null_branch"])  # fmt: skip


def task_key(row: dict) -> tuple:
    return (row["env_id"], row["policy"], row["null_branch"])


def seeds_short(row: dict) -> str:
    """`4 of 5 seeds` where a summary cell holds fewer seeds than its siblings, or than the cells of another
    configuration of its task (summarise), else ""."""
    most = row.get("of_seeds", row["n_seeds"])
    return f"{row['n_seeds']} of {most} seeds" if row["n_seeds"] < most else ""


def short_configurations_note(summary: list[dict]) -> str | None:
    """The line that names the configurations short of seeds in every cell, against the other configurations of
    their task evaluated the same way (a seed lost from all of a configuration's cells), or None."""
    short = sorted({(r["env_id"], series_id(r["variant"], r["series"]), r["config_seeds"], r["of_seeds"])
                    for r in summary if r["config_seeds"] < r["of_seeds"]})  # fmt: skip
    if not short:
        return None
    named = "; ".join(f"{env} {series} ({held} of {most} seeds)" for env, series, held, most in short)
    return (f"note: {len(short)} configuration(s) hold fewer seeds in every cell than the other configurations of "
            f"their task, and say so in the tables: {named}")  # fmt: skip


def short_cells_note(summary: list[dict], shown: int = 5) -> str | None:
    """The line that names the cells with fewer seeds than their siblings, or None where there are none."""
    short = [r for r in summary if r["n_seeds"] < r["config_seeds"]]
    if not short:
        return None
    named = "; ".join(f"{r['env_id']} {series_id(r['variant'], r['series'])} at step {r['step']}, "
                      f"eval γ {r['eval_guidance']:g} ({r['n_seeds']} of {r['config_seeds']} seeds)" for r in short[:shown])  # fmt: skip
    more = f"; and {len(short) - shown} more" if len(short) > shown else ""
    return (f"note: {len(short)} cell(s) hold fewer seeds than the other cells of their configuration, and say so "
            f"in the tables: {named}{more}")  # fmt: skip


def code_of(sources, provenance: dict | None) -> dict:
    """`code` (the revision of the training code behind a cell's runs) and `code_date` (its last commit's
    date, which orders revisions), as the provenance of its CSVs records them; "" where it does not."""
    entries = [provenance_entry(provenance, s) for s in sources] if provenance else []
    dates = {e.get("code_date", "") for e in entries} - {""}
    return {"code": "/".join(sorted({e.get("code", "") for e in entries} - {""})), "code_date": min(dates, default="")}


def mujoco_of(env: str, fields: dict, sources, provenance: dict | None) -> str:
    """The MuJoCo version behind a MuJoCo task's cells: its configuration's `mujoco` field (the one that
    trained it), else its CSVs' provenance."""
    if not is_mujoco(env):
        return ""
    if "mujoco" in fields:
        return fields["mujoco"]
    versions = {provenance_entry(provenance, s).get("mujoco", "") for s in sources} if provenance else set()
    return "/".join(sorted(v for v in versions if v))


# --- provenance ------------------------------------------------------------------------------------


def read_provenance(path: str | None) -> dict:
    """{resolved CSV path: row} from a CSV with columns csv (relative to the repository), commits,
    mujoco, machine, and optional code (the training code's revision), code_date (its commit's date, by
    which figures tell older code) and notes. The repository is the nearest folder above the provenance file
    that holds the listed CSV (an installed copy's own folder holds no results), else this file's."""
    if path is None:
        return {}
    rows = read_csv(path)
    if not rows or "csv" not in rows[0]:
        raise InputError(f"{path} lacks a csv column; see results/provenance.csv")
    folders = [*Path(path).resolve().parents, ROOT]
    return {str(next((f / r["csv"] for f in folders if (f / r["csv"]).exists()), ROOT / r["csv"]).resolve()): r
            for r in rows}  # fmt: skip


def provenance_entry(provenance: dict, source: str) -> dict:
    return provenance.get(str(Path(source).resolve()), {})


def table_csv(rows: list[dict]) -> str:
    """The text of an output CSV of summary-like rows: numbers rounded to 4 places (tiny ones to 4
    significant digits), NaN as an empty field."""
    columns = list(rows[0]) if rows else ["empty"]
    lines = [",".join(columns)] + [",".join(csv_value(r[c]) for c in columns) for r in rows]
    return "\n".join(lines) + "\n"


def csv_value(value) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        return f"{value:.4g}" if value and abs(value) < 1e-3 else str(round(value, 4))
    text = str(value)
    return f'"{text}"' if "," in text else text
