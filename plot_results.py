"""Regenerate the paper's tables and figures from γ-sweep CSVs, and test our numbers against the paper's.

    python plot_results.py sweeps/discrete --runs runs/discrete --compare-paper --output results/discrete

Reads the episodes.csv of one or more sweeps (eval_gamma_sweep.py) and, with --runs, the runs'
TensorBoard events. Every statistic is the one of eval_gamma_sweep.mean_ci95: per training seed the
mean return over the evaluation episodes, then across seeds the mean and a Student-t 95% confidence
interval. Tables and figures show the same numbers.

Configurations are never pooled. A sweep's `config` column names the training configuration (the
variant followed by the training arguments that differ from the defaults, e.g. `ppo mujoco=2.3.7`);
CSVs without it count as config = variant. Where one env and variant hold one configuration, tables
and figures show the variant under the paper's name; where they hold several, each is its own row or
series, labelled by the part of the configuration that differs. Two runs of one configuration with
the same seed, or one cell in two CSVs, are an error naming both.

Writes into --output (and prints each path):
  table_<kind>.md / .tex        the paper's appendix layout: per checkpoint step a PPO row (eval γ=1)
                                and one row per eval γ for each guided variant; one column per env;
                                cells from a MuJoCo other than 2.3.7 are marked †
  table_<kind>_ppo_sweep.*      the vanilla PPO checkpoints swept over γ (not in the paper)
  fig_<kind>_<variant>.png/pdf  the paper's figures: return against training steps, PPO solid black,
                                one dashed viridis line per eval γ, 95% CI as band and error bars;
                                continuous: the paper's six tasks in 2×3, "not run" where no data
  gamma_response_<kind>.png/pdf return against eval γ at one step, one line per variant
  learning_curves.png/pdf       (--runs) episodic training return against steps, mean and CI over seeds
  best_gamma.md / .csv          the best eval γ per env, variant and step
  aggregate_iqm.md / .csv       interquartile mean over envs and seeds of min-max normalised scores,
                                with stratified-bootstrap 95% CIs (scipy.stats.bootstrap)
  compare_paper.md / .csv       (--compare-paper) the agreement report: per paper cell Welch's t test
                                on the two summaries, Holm-corrected over the cells of one table,
                                effect sizes, CI overlap; per env a sign test; CleanRL's published PPO
                                as a second reference; the simulated null rates of each criterion
  provenance.md                 (--provenance) each input CSV with the commits, MuJoCo and machine
                                behind it, and which cells come from it
  controls.md                   when the sweeps hold several evaluation modes (--deterministic,
                                --uniform-null): the modes side by side, cell by cell
"""

import csv
import json
import math
import os
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

from pgg_utils.arguments import RUN_ONLY_ARGS  # noqa: E402



def mean_ci95(values):
    """eval_gamma_sweep.mean_ci95, imported when first needed: the sweep module pulls in torch and the
    training scripts, which a usage error should not wait for."""
    from eval_gamma_sweep import mean_ci95 as sweep_mean_ci95

    return sweep_mean_ci95(values)


def variant_label(train_guidance: float, cond_dropout: float) -> str:
    from eval_gamma_sweep import variant_label as sweep_variant_label

    return sweep_variant_label(train_guidance, cond_dropout)


ROOT = Path(__file__).resolve().parent
PAPER_DATA = ROOT / "data" / "paper_results.csv"
REQUIRED_COLUMNS = {"env_id", "variant", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy",
                    "null_branch", "seed", "return"}  # fmt: skip
PAPER_METHOD_OF_VARIANT = {"ppo": ("ppo", ""), "pgg_g1.1": ("pgg", "1.1")}
# The paper's figure layouts: its envs in its (alphabetical) order; continuous figures are 2×3 with
# every task, one figure per training variant.
PAPER_ENVS = {
    "discrete": ("Acrobot-v1", "CartPole-v1"),
    "continuous": ("HalfCheetah-v4", "Hopper-v4", "Humanoid-v4", "InvertedPendulum-v4", "Pusher-v4", "Walker2d-v4"),
}
PAPER_VARIANTS = ("ppo", "pgg_g1.1", "pgg_drop0.1")
PAPER_SEEDS = 5  # the paper's "mean ± 95% CI" is over 5 seeds (see the README's "The statistic")
# The possible return of a task, where it has one: axes never extend past it.
RETURN_RANGE = {"CartPole-v1": (0.0, 500.0), "Acrobot-v1": (-500.0, 0.0), "InvertedPendulum-v4": (0.0, 1000.0),
                "InvertedPendulum-v5": (0.0, 1000.0)}  # fmt: skip
REFERENCE_MUJOCO = "2.3.7"  # the physics the v4 tasks were written for; other versions are marked
# CleanRL's published PPO benchmark (docs.cleanrl.dev, rl-algorithms/ppo: ppo.py on classic control,
# ppo_continuous_action.py on MuJoCo v4, tag pr-424). Its protocol: per run the mean of the last 100
# *training* episodes' returns at the end of training (500k steps classic control, 1M MuJoCo), then
# mean ± standard deviation over 3 seeds (openrlbenchmark's rlops: numpy std, ddof = 0).
CLEANRL_PPO = {"CartPole-v1": (490.04, 6.12), "Acrobot-v1": (-86.36, 1.32), "Hopper-v4": (2382.86, 271.74),
               "HalfCheetah-v4": (1442.64, 46.03), "Walker2d-v4": (2287.95, 571.78),
               "InvertedPendulum-v4": (963.09, 22.20), "Humanoid-v4": (716.11, 49.08), "Pusher-v4": (-40.38, 7.15)}  # fmt: skip
CLEANRL_SEEDS = 3
CLEANRL_STEPS = {"discrete": 500_000, "continuous": 1_000_000}
ALPHA = 0.05
# Run arguments that do not change what is trained (or only its bits), and the seed: never part of a
# configuration. The training scripts name the former.
NOT_CONFIG_ARGS = RUN_ONLY_ARGS | {"seed"}
MARKERS = "osD^vPX*hp<>"


@dataclass
class Args:
    sweeps: tyro.conf.Positional[tuple[str, ...]] = ()
    """sweep output directories (holding episodes.csv) or episodes.csv files"""
    output: str = "results"
    """directory for every table and figure"""
    runs: tuple[str, ...] = ()
    """run directories or roots whose TensorBoard events give the learning curves"""
    compare_paper: bool = False
    """test our cells against the paper's published numbers (data/paper_results.csv) and CleanRL's PPO"""
    provenance: str | None = None
    """CSV naming, for each input CSV, the commits, MuJoCo version and machine behind it (results/provenance.csv)"""
    paper_layout: bool = True
    """continuous figures in the paper's 2×3 layout, every task ("not run" where there is no data) and a figure per paper variant; --no-paper-layout draws only what was swept"""
    response_step: int | None = None
    """checkpoint step of the γ-response plot; None: the last step of each env"""
    policy: str = "sample"
    """which evaluation policy to report: sample or deterministic"""
    null_branch: str = "learned"
    """which unconditional branch to report: learned or uniform (the temperature-scaling control)"""


USAGE = ("usage: plot_results.py SWEEP [SWEEP ...] [--output DIR] [--runs RUN ...] [--compare-paper] "
         "[--provenance CSV]; SWEEP is a sweep directory holding episodes.csv, or an episodes CSV")  # fmt: skip


class InputError(Exception):
    """Bad input: reported as one line, exit status 2."""


# --- arguments, checked up front ------------------------------------------------------------------


def sweep_csv(raw: str) -> Path:
    path = Path(raw)
    return path / "episodes.csv" if path.is_dir() else path


def run_args_files(run_paths) -> list[Path]:
    files = []
    for raw in run_paths:
        path = Path(raw)
        files.extend([path / "args.json"] if (path / "args.json").is_file() else sorted(path.rglob("args.json")))
    return files


def validate(args: Args) -> None:
    """Every argument, before anything is read at length or written: one InputError for the first problem."""
    if not args.sweeps:
        raise InputError(f"no sweep given. {USAGE}")
    for raw in args.sweeps:
        if not sweep_csv(raw).is_file():
            raise InputError(f"no sweep CSV at {sweep_csv(raw)}")
    for raw in args.runs:
        if not Path(raw).exists():
            raise InputError(f"--runs: no such file or directory: {raw}")
    if args.runs and not run_args_files(args.runs):
        raise InputError(f"--runs: no run (args.json) under {', '.join(args.runs)}")
    if args.provenance is not None and not Path(args.provenance).is_file():
        raise InputError(f"--provenance: no such file: {args.provenance}")
    if args.policy not in ("sample", "deterministic"):
        raise InputError(f"--policy must be sample or deterministic, not {args.policy!r}")
    if args.null_branch not in ("learned", "uniform"):
        raise InputError(f"--null-branch must be learned or uniform, not {args.null_branch!r}")
    if args.response_step is not None and args.response_step <= 0:
        raise InputError(f"--response-step must be a positive step, not {args.response_step}")
    check_writable(Path(args.output))


def check_writable(output: Path) -> None:
    if output.exists() and not output.is_dir():
        raise InputError(f"--output {output} exists and is not a directory")
    try:
        output.mkdir(parents=True, exist_ok=True)
        probe = output / f".plot_results_probe_{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise InputError(f"cannot write to {output}: {e.strerror or e}") from None


# --- reading, configurations ----------------------------------------------------------------------


def read_episodes(paths) -> list[dict]:
    """Every episode row of the given sweeps, each with its `config` (the variant where the CSV has no
    such column) and `_source` (the CSV it came from)."""
    rows = []
    for raw in paths:
        path = sweep_csv(raw)
        if not path.exists():
            raise InputError(f"no sweep CSV at {path}")
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is None:
                raise InputError(f"{path} is empty")
            missing = REQUIRED_COLUMNS - set(reader.fieldnames or [])
            if missing:
                raise InputError(f"{path} lacks columns {sorted(missing)}; is it an episodes.csv of eval_gamma_sweep.py?")
            for row in reader:
                row["config"] = row.get("config") or row["variant"]
                row["_source"] = str(path)
                rows.append(row)
    check_not_pooled(rows)
    return rows


def check_not_pooled(rows: list[dict]) -> None:
    """A cell's seeds must be distinct runs of one configuration, and each episode must be counted once."""
    runs = defaultdict(dict)  # (env, config, seed) -> {run: source}
    episodes = {}
    for row in rows:
        run, source = row.get("run", ""), row["_source"]
        owners = runs[(row["env_id"], row["config"], row["seed"])]
        owners.setdefault(run, source)
        if len(owners) > 1:
            (run_a, source_a), (run_b, source_b) = list(owners.items())[:2]
            raise InputError(f"two runs of configuration '{row['config']}' on {row['env_id']} with seed {row['seed']}: "
                             f"{run_a} ({source_a}) and {run_b} ({source_b}); give them different configs or sweep "
                             "them apart")  # fmt: skip
        key = (row["env_id"], row["config"], row["seed"], run, row["step"], row["eval_guidance"], row["policy"],
               row["null_branch"], row.get("episode", ""))  # fmt: skip
        if key in episodes:
            first = episodes[key]
            where = f"both {first} and {source}" if first != source else f"{source} twice"
            raise InputError(f"episode {key[8]} of run {run} at step {row['step']}, γ {row['eval_guidance']} appears in "
                             f"{where}; pass each sweep once")  # fmt: skip
        episodes[key] = source


def select_mode(rows: list[dict], policy: str, null_branch: str) -> list[dict]:
    selected = [r for r in rows if r["policy"] == policy and r["null_branch"] == null_branch]
    if not selected:
        raise InputError(f"no episodes with policy={policy} and null_branch={null_branch}")
    return selected


def config_tokens(config: str) -> dict:
    """`ppo learning_rate=0.002 mujoco=2.3.7` -> {"learning_rate": "0.002", "mujoco": "2.3.7"}."""
    return dict(token.split("=", 1) for token in config.split()[1:] if "=" in token)


def config_labels(pairs) -> dict:
    """{(env, variant, config, source-set)} -> the label that tells configs of one env and variant apart:
    "" where the env and variant have one config, else the arguments whose values differ
    (`key=default` where a config does not set one), with the source folder added where that is
    still ambiguous."""
    groups = defaultdict(dict)
    for env, variant, config, sources in pairs:
        groups[(env, variant)][config] = sources
    labels = {}
    for (env, variant), configs in groups.items():
        if len(configs) == 1:
            labels.update({(env, variant, c): "" for c in configs})
            continue
        tokens = {c: config_tokens(c) for c in configs}
        keys = sorted({k for t in tokens.values() for k in t})
        differing = [k for k in keys if len({t.get(k) for t in tokens.values()}) > 1]
        named = {c: " ".join(f"{k}={tokens[c].get(k, 'default')}" for k in differing) for c in configs}
        for c in configs:
            if not named[c] or list(named.values()).count(named[c]) > 1:
                folders = sorted({Path(s).parent.name or s for s in configs[c]})
                named[c] = " ".join(filter(None, [named[c], f"from {', '.join(folders)}"]))
            labels[(env, variant, c)] = named[c]
    return labels


def summarise(rows: list[dict], provenance: dict | None = None) -> list[dict]:
    """One row per (env, config, step, γ, policy, null branch): statistics over seeds of the per-seed
    mean episodic return, with the configuration's label (`series`) and MuJoCo version."""
    per_seed = defaultdict(lambda: defaultdict(list))
    sources = defaultdict(set)
    for row in rows:
        key = (row["env_id"], row["variant"], row["config"], int(row["step"]), float(row["eval_guidance"]),
               row["policy"], row["null_branch"])  # fmt: skip
        per_seed[key][int(row["seed"])].append(float(row["return"]))
        sources[key[:3]].add(row["_source"])
    labels = config_labels((*k, frozenset(s)) for k, s in sources.items())
    out = []
    for key in sorted(per_seed, key=lambda k: (k[0], variant_rank(k[1]), k[1], k[2], k[3], k[4], k[5], k[6])):
        env, variant, config, step, gamma, policy, null_branch = key
        seed_means = [float(np.mean(v)) for _, v in sorted(per_seed[key].items())]
        mean, half, _, _ = mean_ci95(seed_means)
        out.append({
            "env_id": env, "variant": variant, "config": config, "series": labels[(env, variant, config)],
            "step": step, "eval_guidance": gamma, "policy": policy, "null_branch": null_branch,
            "n_seeds": len(seed_means), "n_episodes": sum(len(v) for v in per_seed[key].values()),
            "mean": mean, "ci95": half, "sd": float(np.std(seed_means, ddof=1)) if len(seed_means) > 1 else math.nan,
            "seed_means": ";".join(f"{m:.4f}" for m in seed_means), "seeds": sorted(per_seed[key]),
            "mujoco": mujoco_of(env, config, sources[key[:3]], provenance), "sources": sorted(sources[key[:3]]),
        })  # fmt: skip
    return out


def mujoco_of(env: str, config: str, sources, provenance: dict | None) -> str:
    if kind_of(env) != "continuous":
        return ""
    if "mujoco" in config_tokens(config):
        return config_tokens(config)["mujoco"]
    versions = {provenance_entry(provenance, s).get("mujoco", "") for s in sources} if provenance else set()
    return "/".join(sorted(v for v in versions if v))


def variant_rank(variant: str) -> int:
    return PAPER_VARIANTS.index(variant) if variant in PAPER_VARIANTS else len(PAPER_VARIANTS)


def paper_name(variant: str) -> str:
    """The paper's name of a variant: ppo -> PPO, pgg_g1.1 -> PGG, γ_train = 1.1, pgg_drop0.1 -> PGG, dropout 0.1."""
    if variant == "ppo":
        return "PPO"
    if not variant.startswith("pgg_"):
        return variant
    parts = []
    for part in variant[4:].split("_"):
        if part.startswith("g"):
            parts.append(f"γ_train = {part[1:]}")
        elif part.startswith("drop"):
            parts.append(f"dropout {part[4:]}")
        else:
            parts.append(part)
    return "PGG, " + ", ".join(parts)


def series_name(variant: str, series: str) -> str:
    return paper_name(variant) + (f" [{series}]" if series else "")


def series_id(variant: str, series: str) -> str:
    return variant + (f" [{series}]" if series else "")


def ordered_series(summary, variant: str | None = None) -> list[tuple[str, str]]:
    found = {(r["variant"], r["series"]) for r in summary if variant is None or r["variant"] == variant}
    return sorted(found, key=lambda vs: (variant_rank(vs[0]), vs[0], vs[1]))


# --- provenance -----------------------------------------------------------------------------------


def read_provenance(path: str | None) -> dict:
    """{resolved CSV path: row} from a CSV with columns csv (relative to the repository), commits,
    mujoco, machine and optional notes."""
    if path is None:
        return {}
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or "csv" not in rows[0]:
        raise InputError(f"{path} lacks a csv column; see results/provenance.csv")
    return {str((ROOT / r["csv"]).resolve()): r for r in rows}


def provenance_entry(provenance: dict, source: str) -> dict:
    return provenance.get(str(Path(source).resolve()), {})


def provenance_markdown(episodes: list[dict], provenance: dict) -> str:
    per_source = defaultdict(lambda: {"envs": set(), "configs": set(), "seeds": set(), "modes": set(), "rows": 0})
    for row in episodes:
        entry = per_source[row["_source"]]
        entry["envs"].add(row["env_id"])
        entry["configs"].add(row["config"])
        entry["seeds"].add(int(row["seed"]))
        entry["modes"].add(f"{row['policy']}/{row['null_branch']}")
        entry["rows"] += 1
    lines = ["# Provenance", "", "Every cell of the tables and figures beside this file comes from one of these CSVs "
             "(committed in this repository). `commits`: the commits that wrote the CSV "
             "(`git log --format=%h -- CSV`, newest first).", "",
             "| CSV | envs | configs | seeds | evaluation | episodes | commits | MuJoCo | machine | notes |",
             "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for source, e in sorted(per_source.items(), key=lambda kv: relative(kv[0])):
        p = provenance_entry(provenance, source)
        seeds = sorted(e["seeds"])
        lines.append(f"| `{relative(source)}` | {', '.join(sorted(e['envs']))} | {', '.join(sorted(e['configs']))} | "
                     f"{seeds[0]}–{seeds[-1]} | {', '.join(sorted(e['modes']))} | {e['rows']} | {p.get('commits', '?')} | "
                     f"{p.get('mujoco', '?') or '–'} | {p.get('machine', '?')} | {p.get('notes', '')} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def relative(path: str) -> str:
    resolved = Path(path).resolve()
    try:
        return str(resolved.relative_to(ROOT))
    except ValueError:
        return str(path)


# --- tables ---------------------------------------------------------------------------------------


def controls_table(summary_all: list[dict]) -> str:
    """The evaluation modes side by side (sampled or deterministic, learned or uniform null branch),
    on the cells that more than one mode evaluated."""
    modes = sorted({(r["policy"], r["null_branch"]) for r in summary_all})
    by_cell = defaultdict(dict)
    for r in summary_all:
        by_cell[(r["env_id"], series_id(r["variant"], r["series"]), r["step"], r["eval_guidance"])][(r["policy"], r["null_branch"])] = r
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
    """(env, variant, series, step, eval γ) -> summary row."""
    return {(r["env_id"], r["variant"], r["series"], int(r["step"]), float(r["eval_guidance"])): r for r in summary}


def other_mujoco(row: dict | None) -> bool:
    return bool(row and row.get("mujoco") and row["mujoco"] != REFERENCE_MUJOCO)


def fmt_cell(row: dict | None, latex: bool) -> str:
    if row is None:
        return ""
    mean, ci = float(row["mean"]), float(row["ci95"])
    text = f"{mean:.1f}" if math.isnan(ci) else (f"{mean:.1f} \\pm {ci:.1f}" if latex else f"{mean:.1f} ± {ci:.1f}")
    mark = ("^\\dagger" if latex else "†") if other_mujoco(row) else ""
    return f"${text}{mark}$" if latex else text + mark


def step_label(step: int) -> str:
    return f"{step // 1_000_000}M" if step % 1_000_000 == 0 else f"{step // 1000}k"


def gamma_label(gamma: float, latex: bool) -> str:
    return f"$\\gamma={gamma:g}$" if latex else f"γ={gamma:g}"


def table_rows(summary: list[dict], envs: list[str], ppo_sweep: bool, latex: bool):
    """Yields ("section", label) or ("row", label, cells) in the paper's appendix layout."""
    cells = cell_index(summary)
    steps = sorted({int(r["step"]) for r in summary})
    gammas_of = defaultdict(set)
    for r in summary:
        gammas_of[(r["variant"], r["series"])].add(float(r["eval_guidance"]))
    ppo_series = ordered_series(summary, "ppo")
    guided = [vs for vs in ordered_series(summary) if vs[0] != "ppo"]

    def label(variant, series):
        text = series_id(variant, series)
        return text.replace("_", "\\_") if latex else text

    for step in steps:
        yield ("section", f"{step_label(step)} Steps")
        if ppo_sweep:
            for _, series in ppo_series:
                if series:
                    yield ("row", label("ppo", series), None)
                for gamma in sorted(gammas_of[("ppo", series)]):
                    yield ("row", gamma_label(gamma, latex), [fmt_cell(cells.get((e, "ppo", series, step, gamma)), latex) for e in envs])
            continue
        for _, series in ppo_series:
            if any((e, "ppo", series, step, 1.0) in cells for e in envs):
                name = "PPO" + (f" [{series}]" if series else "")
                yield ("row", name, [fmt_cell(cells.get((e, "ppo", series, step, 1.0)), latex) for e in envs])
        for variant, series in guided:
            yield ("row", label(variant, series), None)
            for gamma in sorted(gammas_of[(variant, series)]):
                row_label = ("\\quad " if latex else "  ") + gamma_label(gamma, latex)
                yield ("row", row_label, [fmt_cell(cells.get((e, variant, series, step, gamma)), latex) for e in envs])


def table_notes(summary, envs, latex: bool, paper_layout: bool = True) -> list[str]:
    notes = []
    others = sorted({(r["env_id"], r["mujoco"]) for r in summary if other_mujoco(r)})
    if others:
        where = ", ".join(f"{env} (MuJoCo {version})" for env, version in others)
        recorded = sorted({r["mujoco"] for r in summary if r.get("mujoco") and not other_mujoco(r)})
        rest = f"; the other cells MuJoCo {', '.join(recorded)}" if recorded else ""
        dagger = "$^\\dagger$" if latex else "†"
        notes.append(f"{dagger} from a MuJoCo other than {REFERENCE_MUJOCO}: {where}{rest}.")
    kind = kind_of(envs[0]) if envs else "discrete"
    missing = [e for e in PAPER_ENVS.get(kind, ()) if e not in envs]
    if missing and kind == "continuous" and paper_layout:
        notes.append(f"Not run: {', '.join(missing)}.")
    return notes


def markdown_table(summary, envs, ppo_sweep=False, title="", paper_layout=True) -> str:
    lines = [f"**{title}** (mean ± 95% CI over seeds)", "", "| Method | " + " | ".join(envs) + " |",
             "|---|" + "---|" * len(envs)]  # fmt: skip
    for item in table_rows(summary, envs, ppo_sweep, latex=False):
        if item[0] == "section":
            lines.append(f"| **{item[1]}** |" + " |" * len(envs))
        else:
            lines.append(f"| {item[1]} | " + " | ".join(item[2] or [""] * len(envs)) + " |")
    notes = table_notes(summary, envs, latex=False, paper_layout=paper_layout)
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"


def latex_table(summary, envs, ppo_sweep=False, title="", paper_layout=True) -> str:
    columns = len(envs) + 1
    body = []
    for item in table_rows(summary, envs, ppo_sweep, latex=True):
        if item[0] == "section":
            body += ["\\midrule", f"\\multicolumn{{{columns}}}{{l}}{{\\textbf{{{item[1]}}}}} \\\\"]
        else:
            body.append(" & ".join([item[1], *(item[2] or [""] * len(envs))]) + " \\\\")
    header = " & ".join(["Method", *envs]) + " \\\\"
    notes = [n.replace("γ", "$\\gamma$") for n in table_notes(summary, envs, latex=True, paper_layout=paper_layout)]
    return "\n".join([
        "\\documentclass{article}", "\\usepackage{booktabs}", "\\usepackage[margin=1cm,landscape]{geometry}",
        "\\begin{document}", "\\begin{table}[h]", "\\centering", "\\small",
        f"\\caption{{{title}: mean $\\pm$ 95\\% CI over seeds}}",
        f"\\begin{{tabular}}{{l{'c' * len(envs)}}}", "\\toprule", header, *body, "\\bottomrule", "\\end{tabular}",
        *(["\\par\\smallskip\\footnotesize " + " ".join(notes)] if notes else []),
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
    lines = [",".join(columns)] + [",".join(csv_value(r[c]) for c in columns) for r in rows]
    write(path, "\n".join(lines) + "\n", written)


def csv_value(value) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        return f"{value:.4g}" if value and abs(value) < 1e-3 else str(round(value, 4))
    text = str(value)
    return f'"{text}"' if "," in text else text


def save_figure(fig, stem: Path, written: list) -> None:
    stem.parent.mkdir(parents=True, exist_ok=True)
    for suffix in (".png", ".pdf"):
        path = stem.parent / (stem.name + suffix)  # not with_suffix: "pgg_g1.1" would lose ".1"
        fig.savefig(path, dpi=200, bbox_inches="tight", metadata={"CreationDate": None} if suffix == ".pdf" else None)
        written.append(path)
    plt.close(fig)


# --- figures --------------------------------------------------------------------------------------


def panels(n: int, cols: int | None = None):
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
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    if steps_on_x:
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(steps_formatter))


def not_run(ax, env: str) -> None:
    ax.text(0.5, 0.5, "not run", ha="center", va="center", transform=ax.transAxes, fontsize=10, color="0.45")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_color("0.8")
    ax.set_title(env, fontsize=9)


def set_y_range(ax, env: str, drawn: list, few: bool = False) -> bool:
    """Fits the y-axis to the data, but never past the task's possible returns, and, with fewer than 3
    seeds where the bands dwarf the means (t_{0.975,1} = 12.7), to the means. Marks every band that runs
    past the axis with a triangle at the edge. Returns whether any band was clipped."""
    if not drawn:
        return False
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
    return matplotlib.lines.Line2D([], [], linestyle="none", marker="^", color="0.3", markersize=4,
                                   label="CI runs past the axis (clipped)")  # fmt: skip


def seeds_label(rows) -> str:
    counts = sorted({int(r["n_seeds"]) for r in rows})
    text = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    return f"{text} seed" + ("" if text == "1" else "s")


def panel_title(env: str, rows) -> str:
    """`env (n seeds, MuJoCo v)`, naming the variants run on another MuJoCo where the others were not."""
    extra = [seeds_label(rows)]
    other = [r for r in rows if other_mujoco(r)]
    if other:
        versions = f"MuJoCo {', '.join(sorted({r['mujoco'] for r in other}))}"
        if len(other) < len(rows):
            variants = sorted({r["variant"] for r in other}, key=lambda v: (variant_rank(v), v))
            versions = f"{', '.join(paper_name(v) for v in variants)} on {versions}"
        extra.append(versions)
    return f"{env} ({', '.join(extra)})"


def few_seeds(rows) -> bool:
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
        fig.legend(handles, labels, loc="outside right center", fontsize=7, frameon=False, title=title, title_fontsize=7)


def figure_layout(kind: str, envs: list[str]) -> tuple[list[str], int | None]:
    """The panels of a figure: continuous, the paper's six tasks in 2×3 (and any others after them)."""
    if kind == "continuous":
        layout = list(PAPER_ENVS["continuous"]) + [e for e in envs if e not in PAPER_ENVS["continuous"]]
        return layout, 3
    return list(envs), None


def figure_for_variant(summary, envs, variant, layout: list[str] | None = None, cols: int | None = None):
    """The paper's figure: return against training steps per env; PPO solid black (eval γ=1), one
    dashed line per eval γ of `variant`, viridis from low to high γ, each with its own marker and a
    small sideways offset. Envs of `layout` without data are empty panels labelled "not run"."""
    layout = layout or list(envs)
    cells = cell_index(summary)
    ppo_series = [s for _, s in ordered_series(summary, "ppo")]
    own_series = [s for _, s in ordered_series(summary, variant)] if variant != "ppo" else ppo_series
    gammas = sorted({float(r["eval_guidance"]) for r in summary if r["variant"] == variant})
    if variant == "ppo":
        gammas = [g for g in gammas if g != 1.0]  # γ = 1 is the black PPO line itself
    colours = plt.get_cmap("viridis")(np.linspace(0, 0.9, max(len(gammas), 1)))
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
                label = series_name("ppo", series) + (" (γ = 1)" if variant == "ppo" else "")
                line, data = plot_series(ax, [p[0] for p in points], [p[1] for p in points], errorbars=not few,
                                         band_alpha=0.06 if few else 0.12, color="black",
                                         linestyle=["-", (0, (1, 1)), "-."][i % 3], marker="o", markersize=3, label=label)  # fmt: skip
                drawn.append(data)
                entries.append(((0, i, 0), label, line))
        for j, series in enumerate(own_series):
            for k, (gamma, colour) in enumerate(zip(gammas, colours)):
                points = [(s, cells[(env, variant, series, s, gamma)]) for s in steps if (env, variant, series, s, gamma) in cells]
                if not points:
                    continue
                label = f"γ = {gamma:g}" + (f" [{series}]" if series else "")
                line, data = plot_series(ax, dodge([p[0] for p in points], k, len(gammas), spacing), [p[1] for p in points],
                                         errorbars=not few, band_alpha=0.04 if few else 0.08, color=colour,
                                         linestyle=styles[j % len(styles)], marker=MARKERS[k % len(MARKERS)],
                                         markersize=3, linewidth=1.2, label=label)  # fmt: skip
                drawn.append(data)
                entries.append(((1, j, -gamma), label, line))  # the paper's legend: highest γ first
        any_clipped |= set_y_range(ax, env, drawn, few)
        style_axis(ax, panel_title(env, env_rows), "training steps", "return", steps_on_x=True)
    if any_clipped:
        entries.append(((2, 0, 0), clipped_handle().get_label(), clipped_handle()))
    name = paper_name(variant)
    what = "PPO checkpoints evaluated at each guidance γ (not in the paper)" if variant == "ppo" else f"{name}: evaluated at each guidance γ"
    fig.suptitle(what, fontsize=10)
    legend_right(fig, entries, "mean ± 95% CI over seeds")
    return fig


def gamma_response(summary, envs, step):
    fig, axes = panels(len(envs))
    entries, any_clipped = [], False
    for ax, env in zip(axes, envs):
        env_rows = [r for r in summary if r["env_id"] == env]
        at = step if step is not None else max(int(r["step"]) for r in env_rows)
        few = few_seeds(env_rows)
        drawn = []
        for i, (variant, series) in enumerate(ordered_series(env_rows)):
            points = sorted((r for r in env_rows if r["variant"] == variant and r["series"] == series and int(r["step"]) == at),
                            key=lambda r: float(r["eval_guidance"]))  # fmt: skip
            if points:
                label = series_name(variant, series)
                line, data = plot_series(ax, [float(r["eval_guidance"]) for r in points], points, errorbars=not few,
                                         band_alpha=0.06 if few else 0.12, marker=MARKERS[i % len(MARKERS)],
                                         markersize=3, color="black" if variant == "ppo" else f"C{i}", label=label)  # fmt: skip
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
        title = f"{env} at {step_label(at)} steps\n{panel_title(env, env_rows)[len(env) + 2:-1]}"
        style_axis(ax, title, "eval guidance γ", "return", steps_on_x=False)
    if any_clipped:
        entries.append(((9, "", ""), clipped_handle().get_label(), clipped_handle()))
    legend_right(fig, entries, "training variant")
    return fig


def run_config(run_args: dict, siblings: list[dict]) -> str:
    """The arguments in which a run differs from other runs of its env and variant (seed aside)."""
    keys = sorted({k for a in siblings for k in a} - NOT_CONFIG_ARGS)
    differing = [k for k in keys if len({json.dumps(a.get(k), sort_keys=True) for a in siblings}) > 1]
    return " ".join(f"{k}={run_args.get(k, 'default')}" for k in differing)


def learning_curves(run_paths, output, written, bins: int = 50, min_points: int = 5) -> None:
    """Episodic training return (TensorBoard charts/episodic_return), binned over steps, per variant
    and configuration: mean over seeds of each seed's bin mean, with the t 95% CI. Draws whatever
    points exist and says so in the panel when they are too few for a curve."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    runs, run_dirs = [], []
    for args_file in run_args_files(run_paths):
        run_args = json.loads(args_file.read_text())
        accumulator = EventAccumulator(str(args_file.parent), size_guidance={"scalars": 0})
        accumulator.Reload()
        if "charts/episodic_return" not in accumulator.Tags()["scalars"]:
            continue
        events = accumulator.Scalars("charts/episodic_return")
        variant = variant_label(run_args["guidance"], run_args["cond_dropout"])
        runs.append((run_args, variant, np.array([e.step for e in events]), np.array([e.value for e in events])))
        run_dirs.append(args_file.parent)
    if not runs:
        raise InputError(f"no TensorBoard episodic returns under {', '.join(run_paths)}")
    siblings = defaultdict(list)
    for run_args, variant, _, _ in runs:
        siblings[(run_args["env_id"], variant)].append(run_args)
    curves = defaultdict(list)  # (env, variant, config label) -> [(steps, returns)] per seed
    seen = {}  # (env, variant, config label, seed) -> run directory: one seed is one run
    for (run_args, variant, steps, returns), run_dir in zip(runs, run_dirs):
        label = run_config(run_args, siblings[(run_args["env_id"], variant)])
        first = seen.setdefault((run_args["env_id"], variant, label, run_args["seed"]), run_dir)
        if first != run_dir:
            raise InputError(f"two runs of one configuration and seed {run_args['seed']}: {first} and {run_dir} "
                             "(e.g. runs of two roots or MuJoCo versions); plot them apart")  # fmt: skip
        curves[(run_args["env_id"], variant, label)].append((steps, returns))
    envs = sorted({env for env, _, _ in curves})
    fig, axes = panels(len(envs))
    for ax, env in zip(axes, envs):
        drawn, notes = [], []
        for i, ((curve_env, variant, label), seeds) in enumerate(sorted(curves.items(), key=lambda kv: (variant_rank(kv[0][1]), kv[0]))):
            if curve_env != env:
                continue
            edges = np.linspace(0, max(s.max() for s, _ in seeds) + 1, bins + 1)
            per_seed = np.array([[r[(s >= lo) & (s < hi)].mean() if ((s >= lo) & (s < hi)).any() else np.nan
                                  for lo, hi in zip(edges[:-1], edges[1:])] for s, r in seeds])  # fmt: skip
            centres = (edges[:-1] + edges[1:]) / 2
            present = ~np.isnan(per_seed).all(axis=0)
            stats_per_bin = [mean_ci95(col[~np.isnan(col)]) for col in per_seed.T[present]]
            banded = len(seeds) >= 3  # with 2 seeds t_{0.975,1} = 12.7: a band would cover the panel
            rows = [{"mean": m, "ci95": h if banded else 0.0} for m, h, _, _ in stats_per_bin]
            name = series_name(variant, label) + f" (n={len(seeds)}{'' if banded else ', no CI band'})"
            few = present.sum() < min_points
            _, data = plot_series(ax, centres[present], rows, errorbars=False, band_alpha=0.1 if len(seeds) > 2 else 0.05,
                                  color="black" if variant == "ppo" else f"C{i}", linewidth=1,
                                  marker="o" if few else None, markersize=3, label=name)  # fmt: skip
            drawn.append(data)
            if few:
                count = int(present.sum())
                notes.append(f"{series_name(variant, label)}: only {count} point{'' if count == 1 else 's'}")
        clipped = set_y_range(ax, env, drawn, few=min(len(seeds) for (e, _, _), seeds in curves.items() if e == env) < 3)
        style_axis(ax, env, "training steps", "episodic return", steps_on_x=True)
        handles, labels = ax.get_legend_handles_labels()
        if clipped:
            handles.append(clipped_handle())
            labels.append("CI clipped")
        ax.legend(handles, labels, fontsize=6, frameon=False)
        if notes:
            ax.text(0.02, 0.02, "too few points for a curve:\n" + "\n".join(notes), transform=ax.transAxes, fontsize=6,
                    va="bottom", color="0.3")  # fmt: skip
    save_figure(fig, output / "learning_curves", written)


# --- summaries ------------------------------------------------------------------------------------


def best_gamma(summary) -> list[dict]:
    best = {}
    for r in summary:
        key = (r["env_id"], series_id(r["variant"], r["series"]), int(r["step"]))
        if key not in best or float(r["mean"]) > float(best[key]["mean"]):
            best[key] = r
    return [{"env_id": k[0], "variant": k[1], "step": k[2], "best_eval_guidance": float(r["eval_guidance"]),
             "mean": round(float(r["mean"]), 4), "ci95": round(float(r["ci95"]), 4)} for k, r in sorted(best.items())]  # fmt: skip


def iqm(scores: np.ndarray) -> float:
    return float(stats.trim_mean(scores, 0.25))


def iqm_along(*samples, axis=-1):
    """The IQM of the concatenated samples along `axis`, batched (what scipy.stats.trim_mean(·, 0.25)
    computes, on many resamples at once)."""
    x = np.sort(np.concatenate(samples, axis=axis), axis=axis)
    n = x.shape[axis]
    cut = int(0.25 * n)
    return np.take(x, np.arange(cut, n - cut), axis=axis).mean(axis=axis)


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
        groups[(series_id(r["variant"], r["series"]), int(r["step"]), float(r["eval_guidance"]))].append((seed_means - lo) / ((hi - lo) or 1.0))
    out = []
    for (variant, step, gamma), per_env in sorted(groups.items()):
        point = iqm(np.concatenate(per_env))
        low = high = math.nan
        if all(len(s) >= 2 for s in per_env):
            result = stats.bootstrap(tuple(per_env), iqm_along, vectorized=True, n_resamples=2000,
                                     method="percentile", random_state=0)  # fmt: skip
            low, high = result.confidence_interval
        out.append({"variant": variant, "step": step, "eval_guidance": gamma, "n_envs": len(per_env),
                    "iqm": round(point, 4), "ci_low": round(float(low), 4), "ci_high": round(float(high), 4)})  # fmt: skip
    return out


# --- agreement with the paper ---------------------------------------------------------------------


def sd_from_ci(ci95: float, n: int) -> float:
    """The sample standard deviation behind a Student-t 95% CI half-width over n values."""
    return ci95 * math.sqrt(n) / float(stats.t.ppf(0.975, n - 1))


def welch(mean1: float, sd1: float, n1: int, mean2: float, sd2: float, n2: int) -> tuple[float, float, float]:
    """(t, degrees of freedom, two-sided p) of Welch's t test from summary statistics. With no spread on
    either side the difference is certain: p = 1 if the means are equal, else 0."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2):
        return math.nan, math.nan, math.nan
    v1, v2 = sd1**2 / n1, sd2**2 / n2
    diff = mean1 - mean2
    if v1 + v2 == 0:
        return (0.0 if diff == 0 else math.copysign(math.inf, diff)), math.nan, (1.0 if diff == 0 else 0.0)
    t_value = diff / math.sqrt(v1 + v2)
    df = (v1 + v2) ** 2 / (v1**2 / (n1 - 1) + v2**2 / (n2 - 1))
    return t_value, df, float(2 * stats.t.sf(abs(t_value), df))


def hedges_g(mean1: float, sd1: float, n1: int, mean2: float, sd2: float, n2: int) -> float:
    """Standardised difference (mean1 − mean2) / pooled sd, with Hedges' small-sample correction."""
    if n1 < 2 or n2 < 2 or math.isnan(sd1) or math.isnan(sd2):
        return math.nan
    pooled = math.sqrt(((n1 - 1) * sd1**2 + (n2 - 1) * sd2**2) / (n1 + n2 - 2))
    diff = mean1 - mean2
    if pooled == 0:
        return 0.0 if diff == 0 else math.copysign(math.inf, diff)
    return (1 - 3 / (4 * (n1 + n2) - 9)) * diff / pooled


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error), NaNs left out of the family and kept."""
    indexed = sorted((p, i) for i, p in enumerate(p_values) if not math.isnan(p))
    m = len(indexed)
    adjusted = [math.nan] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(indexed):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


def correct_family(rows: list[dict]) -> None:
    """Sets each row's `p_holm` and `significant` from Holm's correction over these rows' `p`."""
    for row, adjusted in zip(rows, holm([row["p"] for row in rows])):
        row["p_holm"] = adjusted
        row["significant"] = "n/a" if math.isnan(adjusted) else str(adjusted < ALPHA)


def sign_test(differences) -> tuple[int, int, int, float]:
    """(above, below, ties, two-sided exact binomial p) of the signs of ours − reference."""
    above = sum(d > 0 for d in differences)
    below = sum(d < 0 for d in differences)
    ties = len(differences) - above - below
    p = float(stats.binomtest(above, above + below, 0.5).pvalue) if above + below else math.nan
    return above, below, ties, p


def null_rates(n: int = PAPER_SEEDS, draws: int = 200_000, shifts=(0.0, 1.0, 2.0), seed: int = 0) -> list[dict]:
    """Simulated, for two samples of n normal values whose means differ by `shift` standard deviations:
    how often their t 95% CIs overlap, and how often Welch's test rejects at 5%."""
    rng = np.random.default_rng(seed)
    t_crit = float(stats.t.ppf(0.975, n - 1))
    out = []
    for shift in shifts:
        a = rng.standard_normal((draws, n))
        b = rng.standard_normal((draws, n)) + shift
        ma, mb, sa, sb = a.mean(1), b.mean(1), a.std(1, ddof=1), b.std(1, ddof=1)
        overlap = np.abs(ma - mb) <= t_crit * (sa + sb) / math.sqrt(n)
        va, vb = sa**2 / n, sb**2 / n
        t_value = (ma - mb) / np.sqrt(va + vb)
        df = (va + vb) ** 2 / (va**2 / (n - 1) + vb**2 / (n - 1))
        p = 2 * stats.t.sf(np.abs(t_value), df)
        out.append({"shift_sd": shift, "overlap": float(overlap.mean()), "welch_reject": float((p < ALPHA).mean())})
    return out


def our_sd(row: dict) -> float:
    seed_means = [float(x) for x in str(row["seed_means"]).split(";") if x]
    return float(np.std(seed_means, ddof=1)) if len(seed_means) > 1 else math.nan


def compare_row(ours: dict, reference: str, ref_mean: float, ref_ci: float, ref_sd: float, ref_n: int) -> dict:
    n = int(ours["n_seeds"])
    sd = our_sd(ours)
    mean, ci = float(ours["mean"]), float(ours["ci95"])
    t_value, df, p = welch(mean, sd, n, ref_mean, ref_sd, ref_n)
    diff = mean - ref_mean
    overlap = "n/a" if math.isnan(ci) else str(abs(diff) <= ci + ref_ci)
    return {"env_id": ours["env_id"], "variant": ours["variant"], "config": ours["config"], "series": ours["series"],
            "mujoco": ours.get("mujoco", ""), "step": int(ours["step"]), "eval_guidance": float(ours["eval_guidance"]),
            "reference": reference, "ref_mean": ref_mean, "ref_ci95": ref_ci, "ref_sd": ref_sd, "ref_n": ref_n,
            "our_mean": mean, "our_ci95": ci, "our_sd": sd, "our_n": n, "diff": diff,
            "diff_pct": 100 * diff / abs(ref_mean) if ref_mean else math.nan, "welch_t": t_value, "welch_df": df,
            "p": p, "p_holm": math.nan, "significant": "", "hedges_g": hedges_g(mean, sd, n, ref_mean, ref_sd, ref_n),
            "ci_overlap": overlap}  # fmt: skip


def compare_with_paper(summary) -> list[dict]:
    """Our cells beside the paper's, each tested (Welch, Holm over the cells of one of the paper's
    tables, i.e. per kind), and our final PPO cells beside CleanRL's published PPO (Holm over those)."""
    with open(PAPER_DATA, newline="") as f:
        paper = list(csv.DictReader(f))
    paper_envs = {p["env_id"] for p in paper}
    swept = {r["env_id"] for r in summary}
    absent = sorted(swept - paper_envs)
    for env in absent:
        print(f"note: {env} is not in the paper's tables; left out of the comparison", file=sys.stderr)
    if len(absent) == len(swept):
        raise InputError(f"none of the swept envs ({', '.join(absent)}) is in the paper's tables")
    paper_cells = {(p["env_id"], p["method"], p["train_guidance"], int(p["step"]), float(p["eval_guidance"])): p for p in paper}
    out = []
    for r in summary:
        if r["variant"] not in PAPER_METHOD_OF_VARIANT:
            continue
        method, train_guidance = PAPER_METHOD_OF_VARIANT[r["variant"]]
        p = paper_cells.get((r["env_id"], method, train_guidance, int(r["step"]), float(r["eval_guidance"])))
        if p is not None:
            ci = float(p["ci95"])
            out.append(compare_row(r, "paper", float(p["mean"]), ci, sd_from_ci(ci, PAPER_SEEDS), PAPER_SEEDS))
    for kind in ("discrete", "continuous"):
        correct_family([row for row in out if kind_of(row["env_id"]) == kind])
    cleanrl = []
    for r in summary:
        env = r["env_id"]
        if (r["variant"] == "ppo" and env in CLEANRL_PPO and float(r["eval_guidance"]) == 1.0
                and int(r["step"]) == CLEANRL_STEPS[kind_of(env)]):  # fmt: skip
            mean, sd_population = CLEANRL_PPO[env]
            sd = sd_population * math.sqrt(CLEANRL_SEEDS / (CLEANRL_SEEDS - 1))
            ci = float(stats.t.ppf(0.975, CLEANRL_SEEDS - 1)) * sd / math.sqrt(CLEANRL_SEEDS)
            cleanrl.append(compare_row(r, "cleanrl", mean, ci, sd, CLEANRL_SEEDS))
    correct_family(cleanrl)
    return out + cleanrl


def fmt(value: float, digits: int = 1) -> str:
    if isinstance(value, str):
        return value
    if math.isnan(value):
        return "–"
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    return f"{value:.{digits}f}"


def fmt_p(p: float) -> str:
    if math.isnan(p):
        return "–"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def p_is(p: float) -> str:
    """"p = 0.012" or "p < 0.001"."""
    return "p < 0.001" if fmt_p(p).startswith("<") else f"p = {fmt_p(p)}"


def cell_name(r: dict) -> str:
    name = "PPO" if r["variant"] == "ppo" else f"γ_train 1.1 γ={r['eval_guidance']:g}"
    if r["series"]:
        name += f" [{r['series']}]"
    return f"{step_label(r['step'])} {name}"


def env_headline(env: str, rows: list[dict], family_size: int) -> str:
    above, below, ties, p_sign = sign_test([r["diff"] for r in rows])
    significant = [r for r in rows if r["significant"] == "True"]
    raw = sum(1 for r in rows if not math.isnan(r["p"]) and r["p"] < ALPHA)
    overlap = sum(r["ci_overlap"] == "True" for r in rows)
    pct = [abs(r["diff_pct"]) for r in rows if not math.isnan(r["diff_pct"])]
    ratio = [r["ref_sd"] / r["our_sd"] for r in rows if r["our_sd"] and not math.isnan(r["our_sd"]) and r["ref_sd"]]
    versions = sorted({r["mujoco"] for r in rows if r["mujoco"]})
    stack = f" (MuJoCo {', '.join(versions)})" if versions else ""
    text = (f"**{env}**{stack}: {len(rows)} cells; "
            f"**{len(significant)} differ significantly after Holm**")  # fmt: skip
    if significant:
        text += " (" + "; ".join(f"{cell_name(r)}: {fmt(r['our_mean'])} vs {fmt(r['ref_mean'])}, {r['diff_pct']:+.0f}%, "
                                 f"g = {fmt(r['hedges_g'])}" for r in significant) + ")"  # fmt: skip
    text += (f"; {raw} at p < 0.05 before correction. Ours above the paper in {above}, below in {below}"
             f"{f', tied in {ties}' if ties else ''} (sign test {p_is(p_sign)}). "
             f"|difference| {min(pct):.0f}–{max(pct):.0f}% of the paper's mean (median {np.median(pct):.0f}%). "
             f"CIs overlap in {overlap} of {len(rows)}.") if pct else "."  # fmt: skip
    if ratio:
        text += f" The paper's seed spread is {np.median(ratio):.1f}× ours (median over cells)."
    return text


def comparison_markdown(rows: list[dict], summary: list[dict] | None = None) -> str:
    paper_rows = [r for r in rows if r["reference"] == "paper"]
    cleanrl_rows = [r for r in rows if r["reference"] == "cleanrl"]
    lines = ["# Agreement with the paper", ""]
    families = {kind: [r for r in paper_rows if kind_of(r["env_id"]) == kind] for kind in ("discrete", "continuous")}
    lines.append("## Headline")
    lines.append("")
    for kind, family in families.items():
        if not family:
            continue
        n_sig = sum(r["significant"] == "True" for r in family)
        lines.append(f"{len(family)} cells of the paper's {kind} table compared; **{n_sig} differ significantly** "
                     f"(Welch's t, Holm-corrected over these {len(family)} cells, family-wise α = {ALPHA}).")  # fmt: skip
        lines.append("")
        for env in sorted({r["env_id"] for r in family}):
            lines.append("- " + env_headline(env, [r for r in family if r["env_id"] == env], len(family)))
        lines.append("")
    if not paper_rows:
        lines += ["No cell of the paper's tables was swept (its steps are 100k–500k discrete, 200k–1M continuous).", ""]
    configs = sorted({(r["env_id"], r["variant"], r["series"]) for r in paper_rows if r["series"]})
    if configs:
        lines += ["Several configurations of one env and variant are compared with the paper separately: "
                  + "; ".join(f"{e} {v} [{s}]" for e, v, s in configs) + ".", ""]  # fmt: skip
    if cleanrl_rows:
        lines.append("CleanRL's published PPO, a second reference (its own protocol): " + "; ".join(
            f"{r['env_id']} ours {fmt(r['our_mean'])} vs {fmt(r['ref_mean'])} ({r['diff_pct']:+.0f}%, Holm {p_is(r['p_holm'])})"
            for r in cleanrl_rows) + ".")  # fmt: skip
        lines.append("")
    short = sorted({r["env_id"] for r in summary or [] if r["env_id"] in CLEANRL_PPO and r["variant"] == "ppo"}
                   - {r["env_id"] for r in cleanrl_rows})  # fmt: skip
    if short:
        lines += [f"No PPO cell at CleanRL's final step (500k classic control, 1M MuJoCo) for {', '.join(short)}; "
                  "not compared with CleanRL.", ""]  # fmt: skip
    lines += criteria_section()
    lines += ["## Cells", "",
              "Our side: the per-seed mean returns (sd over seeds, ddof 1). The paper's: sd recovered from its "
              f"mean ± 95% CI with n = {PAPER_SEEDS} (sd = CI·√5 / t₀.₉₇₅,₄). diff = ours − paper; g = Hedges' g "
              "(positive: ours higher). Holm: over the cells of the same table (discrete or continuous). "
              "† MuJoCo other than 2.3.7.", "",
              "| env | variant | step | eval γ | paper | ours | seeds | diff | diff % | Welch p | Holm p | g | CIs overlap |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in paper_rows:
        mark = " ✗" if r["significant"] == "True" else ""
        variant = series_id(r["variant"], r["series"]) + ("†" if r["mujoco"] and r["mujoco"] != REFERENCE_MUJOCO else "")
        lines.append(f"| {r['env_id']} | {variant} | {step_label(r['step'])} | {r['eval_guidance']:g} | "
                     f"{fmt(r['ref_mean'])} ± {fmt(r['ref_ci95'])} | {fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                     f"{r['our_n']} | {r['diff']:+.1f} | {fmt(r['diff_pct'])} | {fmt_p(r['p'])} | {fmt_p(r['p_holm'])}{mark} | "
                     f"{fmt(r['hedges_g'], 2)} | {'yes' if r['ci_overlap'] == 'True' else 'no' if r['ci_overlap'] == 'False' else '?'} |")  # fmt: skip
    if cleanrl_rows:
        lines += ["", "## Second reference: CleanRL's PPO", "",
                  "CleanRL's published end-of-training PPO returns (docs.cleanrl.dev, `ppo.py` on classic control at "
                  "500k steps, `ppo_continuous_action.py` on MuJoCo v4 at 1M): per run the mean return of the last "
                  "100 *training* episodes, then **mean ± standard deviation** over 3 seeds (numpy std, ddof 0; "
                  "not a CI). Ours: vanilla PPO's final checkpoint evaluated over 50 fresh episodes per seed at γ = 1. "
                  "The protocols differ (training episodes under the running policy vs evaluation of the final "
                  "weights), so the test is indicative. sd in units: ours − CleanRL over CleanRL's sd (ddof 1).", "",
                  "| env | CleanRL (mean ± sd, 3 seeds) | paper PPO, same step | ours PPO | diff % | in CleanRL sds | Welch p | Holm p |",
                  "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        paper_ppo = {(r["env_id"], r["step"], r["series"]): r for r in paper_rows if r["variant"] == "ppo" and r["eval_guidance"] == 1.0}
        for r in cleanrl_rows:
            p = paper_ppo.get((r["env_id"], r["step"], r["series"]))
            sd_pop = CLEANRL_PPO[r["env_id"]][1]
            paper_cell = f"{fmt(p['ref_mean'])} ± {fmt(p['ref_ci95'])}" if p else "–"
            lines.append(f"| {r['env_id']} | {fmt(r['ref_mean'], 2)} ± {sd_pop:.2f} | "
                         f"{paper_cell} | {fmt(r['our_mean'])} ± {fmt(r['our_ci95'])} | "
                         f"{r['diff_pct']:+.1f} | {r['diff'] / r['ref_sd']:+.2f} | {fmt_p(r['p'])} | {fmt_p(r['p_holm'])} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def criteria_section() -> list[str]:
    rates = null_rates()
    by_shift = {r["shift_sd"]: r for r in rates}
    null = by_shift[0.0]
    lines = ["## What each criterion can and cannot show", "",
             f"Simulated (seeded, {200_000:,} pairs): two samples of {PAPER_SEEDS} normal values, means "
             "`shift` standard deviations apart.", "",
             "| true difference | 95% CIs overlap | Welch p < 0.05 |", "|---|---|---|"]  # fmt: skip
    for r in rates:
        lines.append(f"| {r['shift_sd']:g} sd | {100 * r['overlap']:.1f}% | {100 * r['welch_reject']:.1f}% |")
    lines += ["",
              f"- **CI overlap** happens {100 * null['overlap']:.1f}% of the time when both samples come from one "
              "distribution, and still most of the time for a true difference of one standard deviation: it almost "
              "never fails, so a cell that 'agrees' this way says little. Where one side's interval is wide (the "
              "paper's HalfCheetah), it says nothing.",
              f"- **Welch's t test** per cell rejects a true null {100 * null['welch_reject']:.1f}% of the time at "
              "p < 0.05; after Holm's correction over a table of hundreds of cells, only large, clear differences "
              "survive. A non-significant cell is *not* evidence of equality (5 seeds give little power), "
              "only the absence of evidence of a difference; an equivalence test would need a margin the paper "
              "does not give. Holm is valid whatever the dependence between cells.",
              "- **The sign test** per env asks whether ours lies above the paper's as often as below. Its cells are "
              "not independent (the same 5 checkpoints are evaluated at every eval γ, and checkpoints of one run "
              "share its history), so its p-value overstates the evidence; read it as a description of a "
              "systematic offset, not a test.",
              "- **The effect size** (Hedges' g, difference as % of the paper's mean) says how large a difference "
              "is, whatever its p-value.", ""]  # fmt: skip
    return lines


def simple_markdown(rows: list[dict]) -> str:
    columns = list(rows[0])
    return "\n".join(["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
                     + ["| " + " | ".join(str(r[c]) for c in columns) + " |" for r in rows]) + "\n"  # fmt: skip


# --- main -----------------------------------------------------------------------------------------


def generate(args: Args) -> list[Path]:
    validate(args)
    output = Path(args.output)
    provenance = read_provenance(args.provenance)
    episodes = read_episodes(args.sweeps)
    summary = summarise(select_mode(episodes, args.policy, args.null_branch), provenance)
    written: list[Path] = []
    if len({(r["policy"], r["null_branch"]) for r in episodes}) > 1:
        write(output / "controls.md", controls_table(summarise(episodes, provenance)), written)
    if args.provenance:
        write(output / "provenance.md", provenance_markdown(episodes, provenance), written)
    by_kind = defaultdict(list)
    for r in summary:
        by_kind[kind_of(r["env_id"])].append(r)
    for kind, rows in sorted(by_kind.items()):
        envs = sorted({r["env_id"] for r in rows})
        title = f"{kind.capitalize()} environments"
        layout_args = {"title": title, "paper_layout": args.paper_layout}
        write(output / f"table_{kind}.md", markdown_table(rows, envs, **layout_args), written)
        write(output / f"table_{kind}.tex", latex_table(rows, envs, **layout_args), written)
        ppo_gammas = {float(r["eval_guidance"]) for r in rows if r["variant"] == "ppo"}
        if len(ppo_gammas) > 1:
            title = f"Vanilla PPO checkpoints swept over eval guidance ({kind})"
            layout_args = {"title": title, "paper_layout": args.paper_layout}
            write(output / f"table_{kind}_ppo_sweep.md", markdown_table(rows, envs, True, **layout_args), written)
            write(output / f"table_{kind}_ppo_sweep.tex", latex_table(rows, envs, True, **layout_args), written)
        layout, cols = figure_layout(kind, envs) if args.paper_layout else (envs, None)
        paper_variants = set(PAPER_VARIANTS) if kind == "continuous" and args.paper_layout else set()
        variants = sorted({r["variant"] for r in rows} | paper_variants, key=lambda v: (variant_rank(v), v))
        for variant in variants:
            save_figure(figure_for_variant(rows, envs, variant, layout, cols), output / f"fig_{kind}_{variant}", written)
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
        write(output / "compare_paper.md", comparison_markdown(comparison, summary), written)
    return written


def main() -> None:
    args = tyro.cli(Args)
    try:
        written = generate(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except OSError as e:
        print(f"error: cannot write {e.filename or args.output}: {e.strerror or e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted; the outputs written so far are complete files", file=sys.stderr)
        sys.exit(130)
    for path in written:
        print(path)


if __name__ == "__main__":
    main()
