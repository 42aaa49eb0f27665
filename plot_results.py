"""Regenerate the paper's tables and figures from γ-sweep CSVs, and test our numbers against the paper's.

    python plot_results.py sweeps/discrete --runs runs/discrete --compare-paper --output results/discrete

Reads the episodes.csv of one or more sweeps (eval_gamma_sweep.py) and, with --runs, the runs'
TensorBoard events. Every statistic is the one of pgg_utils.episodes.mean_ci95: per training seed the
mean return over the evaluation episodes, then across seeds the mean and a Student-t 95% confidence
interval. Tables and figures show the same numbers. The report against the paper and CleanRL is
paper_study.agreement's; the figures are drawn by paper_study.figures.

Configurations are never pooled. A sweep's `config` column names the training configuration (the
variant followed by the training arguments that differ from the defaults, e.g. `ppo mujoco=2.3.7`);
CSVs without it count as config = variant. A configuration is that label with the exact training
guidance and dropout of its rows (the label rounds them to 6 digits). Where one env and variant hold
one configuration, tables and figures show the variant under the paper's name, with a fork's script
(`script=`), named wherever it trained; where they hold several, each is its own row or series,
labelled by the fields that differ (and a fork's script): the sweep's
`config_fields` column (the label's parts as JSON, never parsed from the label but in CSVs without it). Two
runs of one configuration with the same seed, or one cell in two CSVs, are an error naming both. An
env's table (discrete or continuous) is its rows' `action_space`, or where a CSV lacks that column,
the action space of the task itself.

Writes into --output (and prints each path):
  table_<kind>.md / .tex        the paper's appendix layout: per checkpoint step a PPO row (eval γ=1)
                                and one row per eval γ for each guided variant; one column per env;
                                cells from a MuJoCo other than 2.3.7 are marked †
  table_<kind>_ppo_sweep.*      the vanilla PPO checkpoints swept over γ (not in the paper)
  fig_<kind>_<variant>.png/pdf  the paper's figures: return against training steps, PPO solid black,
                                one dashed line per eval γ (one colour per γ in every figure), 95% CI
                                as band and error bars; only the tasks and variants swept, in the paper's
                                order and its 2×3 grid where the tasks are all the paper's; the continuous
                                dropout figure the paper's γ 1.0-1.2 only, the other swept γ in
                                fig_continuous_pgg_drop0.1_beyond_paper
  gamma_response_<kind>.png/pdf return against eval γ at one step, one line per variant
  learning_curves.png/pdf       (--runs) episodic training return against steps, mean and CI over seeds
  best_gamma.md / .csv          the best eval γ per env, variant and step
  aggregate_iqm.md / .csv       interquartile mean over envs and seeds of scores normalised by fixed
                                references (0 = the paper's PPO at its first step, 1 = at its last;
                                on a task the paper did not run, the sweep's own PPO at eval γ = 1, and
                                the table and figures say which; a task with neither is left out, with
                                a printed note), with stratified-bootstrap 95% CIs (scipy.stats.bootstrap);
                                aggregate_iqm_<kind>.png/pdf draws the last step's as intervals
  performance_profile_<kind>.png/pdf  rliable's performance profile of the same normalised scores at
                                the last step: per variant and eval γ the fraction of (task, seed)
                                scores above each τ, with a stratified-bootstrap 95% CI, over the
                                scores' range
  compare_paper.md / .csv       (--compare-paper) the agreement report: per paper cell Welch's t test
                                on the two summaries, Holm-corrected over the cells of one table,
                                effect sizes, CI overlap and the gap its test detects 80% of the time;
                                per env a sign test and the median relative gap with a bootstrap CI
                                over our seeds; CleanRL's published PPO as a second reference; the
                                simulated null rates of each criterion. Of the paper's configurations
                                only: a fork (`script=` in its label) or any other training argument
                                is left out and named, in the report and a printed note
  compare_paper_tasks.csv       (--compare-paper) the per-env lines of the report's headline
  provenance.md                 (--provenance) each input CSV with the commits, MuJoCo and machine
                                behind it, and which cells come from it
  controls.md                   when the sweeps hold several evaluation modes (--deterministic,
                                --uniform-null): the modes side by side, cell by cell
  outputs.txt                   the files above that this run wrote, each with its sha256. A rerun into
                                the same folder removes those the previous run listed and it did not
                                write again (a previous grid's figures; learning curves a rerun without
                                --runs does not draw), where they are still the bytes it recorded; a
                                file edited since, or a name added by hand, is kept, with a note

--output is locked while it is written (a second plot_results.py or reproduce.py into it is refused).
Partial inputs are never tabled as whole: an episodes.csv that differs from its sweep's written.csv
(rows and sha256) is refused; without one, so is a cell with fewer episodes than the file's other cells,
and a cell with fewer seeds than the other cells of its configuration is named in a printed note and
in the tables ("(4 of 5 seeds)"). --runs draws only whole runs: one whose events hold no episodic
return or end before its total_timesteps or its last checkpoint is left out and named (a printed note,
and in its panel).
"""

from pgg_utils import startup  # first: a Ctrl-C during the imports below is one line, status 130

# isort: split
import json
import logging
import math
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, never a display; before paper_study.figures imports pyplot
import numpy as np
import tyro

from paper_study import figures
from paper_study.aggregate import aggregate_iqm, normalisation_references, performance_profiles, reference_text
from paper_study.agreement import (
    REFERENCE_MUJOCO,
    compare_with_paper,
    comparison_markdown,
    other_mujoco,
    series_id,
    step_label,
    task_summaries,
)
from paper_study.figures import cell_index, ordered_series
from paper_study.paper import PAPER_ENVS, is_paper_configuration, paper_name, paper_rows, series_name, variant_rank
from paper_study.summary import (
    ROOT,
    config_labels,
    provenance_entry,
    read_provenance,
    seeds_short,
    short_cells_note,
    short_configurations_note,
    summarise,
    table_csv,
    table_kinds,
)
from pgg_utils import files
from pgg_utils.episodes import episodes_csv as sweep_csv
from pgg_utils.episodes import read_episodes, select_mode
from pgg_utils.files import (
    MANIFEST,
    InputError,
    LockedError,
    read_manifest,
    remove_stale,
    write_atomic,
    write_manifest,
)
from pgg_utils.identity import Configuration

NULL_BRANCHES = ("learned", "uniform", "bc")  # the sweep's null_branch column
# The eval γ a paper figure draws where it is fewer than its table's (its continuous dropout figure: 1.0-1.2).
# Our figure of that variant draws the same range; the other swept γ go to fig_<kind>_<variant>_beyond_paper.
PAPER_FIGURE_GAMMAS = {("continuous", "pgg_drop0.1"): (1.0, 1.2)}


@dataclass
class Args:
    sweeps: tyro.conf.Positional[tuple[str, ...]] = ()
    """sweep output directories (holding episodes.csv) or episodes.csv files"""
    output: str = "plots"
    """directory for every table and figure (not the committed results/ unless named)"""
    runs: tuple[str, ...] = ()
    """run directories or roots whose TensorBoard events give the learning curves"""
    compare_paper: bool = False
    """test our cells against the paper's published numbers (paper_study/data/paper_results.csv) and CleanRL's PPO"""
    provenance: str | None = None
    """CSV naming, for each input CSV, the commits, MuJoCo version and machine behind it (results/provenance.csv)"""
    response_step: int | None = None
    """checkpoint step of the γ-response plot; None: the last step of each env"""
    policy: str = "sample"
    """which evaluation policy to report: sample or deterministic"""
    null_branch: str = "learned"
    """which unconditional branch to report: learned, uniform (the temperature-scaling control) or bc (fitted by pgg_utils.bc_null)"""


USAGE = ("usage: plot_results.py SWEEP [SWEEP ...] [--output DIR] [--runs RUN ...] [--compare-paper] "
         "[--provenance CSV]; SWEEP is a sweep directory holding episodes.csv, or an episodes CSV")  # fmt: skip


# --- arguments, checked up front ------------------------------------------------------------------


def run_args_files(run_paths) -> list[Path]:
    """The args.json of each run: a folder holding one is a run, any other folder every run below it (links to
    run directories followed)."""
    found = []
    for raw in run_paths:
        path = Path(raw)
        found.extend([path / "args.json"] if (path / "args.json").is_file() else files.files_under(path, "args.json"))
    return found


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
    if args.null_branch not in NULL_BRANCHES:
        raise InputError(f"--null-branch must be one of {', '.join(NULL_BRANCHES)}, not {args.null_branch!r}")
    if args.response_step is not None and args.response_step <= 0:
        raise InputError(f"--response-step must be a positive step, not {args.response_step}")
    check_writable(Path(args.output))


def check_writable(output: Path) -> None:
    if output.exists() and not output.is_dir():
        raise InputError(f"--output {output} exists and is not a directory")
    files.check_writable(output)


# --- training curves (--runs) ---------------------------------------------------------------------


def training_curves(run_paths) -> tuple[dict, list[tuple[str, Path, str]]]:
    """({(env, variant, series): [(steps, returns) per seed]}, [(env, run directory, why) per run left
    out]): the episodic training returns (TensorBoard charts/episodic_return) of the runs under
    `run_paths`. A run's configuration is its last checkpoint's (identity.Configuration.key: the
    script and every training argument, the sweep's and the tables' key), and its series is labelled as
    the tables label theirs (config_labels), so a curve and a table row of one configuration carry one
    name. Only whole runs are drawn: a run whose events hold no episodic returns (missing or damaged) or
    end before its total_timesteps (cut or damaged events, or an unfinished run), or that has no readable
    checkpoint, is left out and named (incomplete_run); one whose args.json disagrees with its
    checkpoints is refused (runs.record_error)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from pgg_utils import checkpoints, runs  # torch: only where --runs is given

    found, left_out = [], []  # (configuration, seed, steps, returns, run directory); (env, run directory, why)
    fields = {}  # configuration -> its label's fields
    for args_file in run_args_files(run_paths):
        run_dir = args_file.parent
        ckpt = checkpoints.last_readable(run_dir)[1]
        if error := runs.record_error(run_dir, ckpt):
            raise InputError(error)
        run_args = ckpt["args"] if ckpt else json.loads(args_file.read_text())
        # A resumed run's events overlap the first session's past its checkpoint: the reader drops them,
        # as it should, with a warning per file that is no news to the user.
        logging.getLogger("tensorboard").setLevel(logging.ERROR)
        accumulator = EventAccumulator(str(run_dir), size_guidance={"scalars": 0})
        accumulator.Reload()
        why = incomplete_run(run_dir, run_args, accumulator) or (None if ckpt else "it has no readable checkpoint")
        if why:
            left_out.append((run_args.get("env_id", "?"), run_dir, why))
            continue
        events = accumulator.Scalars("charts/episodic_return")
        configuration = Configuration.of_checkpoint(ckpt)
        config = configuration.key
        fields.setdefault(config, configuration.label_fields())
        steps, returns = np.array([e.step for e in events]), np.array([e.value for e in events])
        found.append((config, run_args["seed"], steps, returns, run_dir))
    if not found:
        why = f": {'; '.join(f'{run_dir}: {why}' for _, run_dir, why in left_out)}" if left_out else ""
        raise InputError(f"no TensorBoard episodic returns under {', '.join(run_paths)} of a whole run{why}")
    sources = defaultdict(set)
    for config, _, _, _, run_dir in found:
        sources[config].add(str(run_dir.parent))
    labels = config_labels({config: (fields[config], folders) for config, folders in sources.items()})
    curves = defaultdict(list)  # (env, variant, series) -> [(steps, returns)] per seed
    seen = {}  # (configuration, seed) -> run directory: one seed is one run
    for config, seed, steps, returns, run_dir in found:
        first = seen.setdefault((config, seed), run_dir)
        if first != run_dir:
            raise InputError(f"two runs of one configuration and seed {seed}: {first} and {run_dir} "
                             "(e.g. runs of two roots); plot them apart")  # fmt: skip
        curves[(config[0], config[1], labels[config])].append((steps, returns))
    return curves, left_out


def incomplete_run(run_dir: Path, run_args: dict, accumulator) -> str | None:
    """Why a run's TensorBoard events cannot be drawn as a whole run, or None where they can: they hold
    no episodic return, or they end (the last step of any scalar; every training iteration logs its
    losses at its global step) before the run's total_timesteps or its last checkpoint."""
    from pgg_utils.checkpoints import checkpoint_step, checkpoints_of  # torch: only where --runs is given

    tags = accumulator.Tags()["scalars"]
    if "charts/episodic_return" not in tags:
        return "its TensorBoard events hold no episodic return (missing or damaged)"
    events_end = max(event.step for tag in tags for event in accumulator.Scalars(tag))
    checkpoint_end = max((checkpoint_step(path) for path in checkpoints_of(run_dir)), default=0)
    total = run_args.get("total_timesteps")
    if events_end >= max(checkpoint_end, total if isinstance(total, int) else 0):
        return None
    if checkpoint_end > events_end:
        return f"its events end at step {events_end:,}, its checkpoints at {checkpoint_end:,} (cut or damaged)"
    return f"its events end at step {events_end:,} of its {total:,} (unfinished)"


# --- provenance -----------------------------------------------------------------------------------


def provenance_markdown(episodes: list[dict], provenance: dict) -> str:
    per_source = defaultdict(lambda: {"envs": set(), "configs": set(), "seeds": set(), "modes": set(), "rows": 0})
    for row in episodes:
        entry = per_source[row["_source"]]
        entry["envs"].add(row["env_id"])
        entry["configs"].add(row["config"])
        entry["seeds"].add(int(row["seed"]))
        entry["modes"].add(f"{row['policy']}/{row['null_branch']}")
        entry["rows"] += 1
    lines = ["# Provenance", "", ("Every cell of the tables and figures beside this file comes from one of these CSVs "
                                  "(committed in this repository). `commits`: the commits that wrote the CSV "
                                  "(`git log --format=%h -- CSV`, newest first)."), "",
             ("| CSV | envs | configs | seeds | evaluation | episodes | commits | MuJoCo | machine | training code "
              "| notes |"), "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for source, e in sorted(per_source.items(), key=lambda kv: relative(kv[0])):
        p = provenance_entry(provenance, source)
        seeds = sorted(e["seeds"])
        lines.append(f"| `{relative(source)}` | {', '.join(sorted(e['envs']))} | {', '.join(sorted(e['configs']))} | "
                     f"{seeds[0]}–{seeds[-1]} | {', '.join(sorted(e['modes']))} | {e['rows']} | {p.get('commits', '?')} | "
                     f"{p.get('mujoco', '?') or '–'} | {p.get('machine', '?')} | {p.get('code', '?')} | "
                     f"{p.get('notes', '')} |")  # fmt: skip
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
        by_cell[(r["env_id"], series_id(r["variant"], r["series"]), r["step"], r["eval_guidance"])][
            (r["policy"], r["null_branch"])
        ] = r
    lines = ["| env | variant | step | eval γ | " + " | ".join(f"{p}, {n} null" for p, n in modes) + " |",
             "|---|---|---|---|" + "---|" * len(modes)]  # fmt: skip
    for (env, variant, step, gamma), cells in sorted(by_cell.items()):
        if len(cells) > 1:
            values = [fmt_cell(cells.get(mode), latex=False) for mode in modes]
            lines.append(f"| {env} | {variant} | {step_label(step)} | {gamma:g} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def fmt_cell(row: dict | None, latex: bool) -> str:
    if row is None:
        return ""
    mean, ci = float(row["mean"]), float(row["ci95"])
    text = f"{mean:.1f}" if math.isnan(ci) else (f"{mean:.1f} \\pm {ci:.1f}" if latex else f"{mean:.1f} ± {ci:.1f}")
    mark = ("^\\dagger" if latex else "†") if other_mujoco(row) else ""
    short = f" ({seeds_short(row)})" if seeds_short(row) else ""
    return f"${text}{mark}${short}" if latex else text + mark + short


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
                    yield (
                        "row",
                        gamma_label(gamma, latex),
                        [fmt_cell(cells.get((e, "ppo", series, step, gamma)), latex) for e in envs],
                    )
            continue
        for _, series in ppo_series:
            if any((e, "ppo", series, step, 1.0) in cells for e in envs):
                name = series_name("ppo", series)
                yield ("row", name, [fmt_cell(cells.get((e, "ppo", series, step, 1.0)), latex) for e in envs])
        for variant, series in guided:
            yield ("row", label(variant, series), None)
            for gamma in sorted(gammas_of[(variant, series)]):
                row_label = ("\\quad " if latex else "  ") + gamma_label(gamma, latex)
                yield ("row", row_label, [fmt_cell(cells.get((e, variant, series, step, gamma)), latex) for e in envs])


def table_notes(summary, envs, latex: bool) -> list[str]:
    notes = []
    others = sorted({(r["env_id"], r["mujoco"]) for r in summary if other_mujoco(r)})
    if others:
        where = ", ".join(f"{env} (MuJoCo {version})" for env, version in others)
        recorded = sorted({r["mujoco"] for r in summary if r.get("mujoco") and not other_mujoco(r)})
        rest = f"; the other cells MuJoCo {', '.join(recorded)}" if recorded else ""
        dagger = "$^\\dagger$" if latex else "†"
        notes.append(f"{dagger} from a MuJoCo other than {REFERENCE_MUJOCO}: {where}{rest}.")
    return notes


def markdown_table(summary, envs, ppo_sweep=False, title="") -> str:
    lines = [f"**{title}** (mean ± 95% CI over seeds)", "", "| Method | " + " | ".join(envs) + " |",
             "|---|" + "---|" * len(envs)]  # fmt: skip
    for item in table_rows(summary, envs, ppo_sweep, latex=False):
        if item[0] == "section":
            lines.append(f"| **{item[1]}** |" + " |" * len(envs))
        else:
            lines.append(f"| {item[1]} | " + " | ".join(item[2] or [""] * len(envs)) + " |")
    notes = table_notes(summary, envs, latex=False)
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"


def latex_table(summary, envs, ppo_sweep=False, title="") -> str:
    columns = len(envs) + 1
    body = []
    for item in table_rows(summary, envs, ppo_sweep, latex=True):
        if item[0] == "section":
            body += ["\\midrule", f"\\multicolumn{{{columns}}}{{l}}{{\\textbf{{{item[1]}}}}} \\\\"]
        else:
            body.append(" & ".join([item[1], *(item[2] or [""] * len(envs))]) + " \\\\")
    header = " & ".join(["Method", *envs]) + " \\\\"
    notes = [n.replace("γ", "$\\gamma$") for n in table_notes(summary, envs, latex=True)]
    return "\n".join([
        "\\documentclass{article}", "\\usepackage{booktabs}", "\\usepackage[margin=1cm,landscape]{geometry}",
        "\\begin{document}", "\\begin{table}[h]", "\\centering", "\\small",
        f"\\caption{{{title}: mean $\\pm$ 95\\% CI over seeds}}",
        f"\\begin{{tabular}}{{l{'c' * len(envs)}}}", "\\toprule", header, *body, "\\bottomrule", "\\end{tabular}",
        *(["\\par\\smallskip\\footnotesize " + " ".join(notes)] if notes else []),
        "\\end{table}", "\\end{document}", "",
    ])  # fmt: skip


def write(path: Path, data: str | bytes, written: list) -> None:
    """Writes one output atomically (a complete file or none) and records it in `written`."""
    write_atomic(path, data)
    written.append(path)


def write_csv(path: Path, rows: list[dict], written: list) -> None:
    write(path, table_csv(rows), written)


def save_figure(fig, stem: Path, written: list) -> None:
    """`stem`.png and `stem`.pdf (not with_suffix: "pgg_g1.1" would lose ".1"), written atomically like
    every other output."""
    for image_format, image in figures.render(fig).items():
        write(stem.parent / f"{stem.name}.{image_format}", image, written)


# --- summaries ------------------------------------------------------------------------------------


def best_gamma(summary) -> list[dict]:
    best = {}
    for r in summary:
        key = (r["env_id"], series_id(r["variant"], r["series"]), int(r["step"]))
        if key not in best or float(r["mean"]) > float(best[key]["mean"]):
            best[key] = r
    return [{"env_id": k[0], "variant": k[1], "step": k[2], "best_eval_guidance": float(r["eval_guidance"]),
             "mean": round(float(r["mean"]), 4), "ci95": round(float(r["ci95"]), 4)} for k, r in sorted(best.items())]  # fmt: skip


def simple_markdown(rows: list[dict]) -> str:
    columns = list(rows[0])
    return "\n".join(["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
                     + ["| " + " | ".join(str(r[c]) for c in columns) + " |" for r in rows]) + "\n"  # fmt: skip


# --- main -----------------------------------------------------------------------------------------


def generate(args: Args) -> list[Path]:
    """Writes every output into --output, then its manifest, and removes the files the previous run
    listed and this one did not write, holding --output's lock throughout. Returns the paths written.
    An interrupted run leaves a manifest of what either run wrote, so that the next run still finds
    every file to remove."""
    validate(args)
    lock = claim_output(Path(args.output))
    try:
        return generate_locked(args)
    finally:
        lock.close()


def claim_output(output: Path, flag: str = "--output"):
    """The lock of an output folder (files.lock_directory), held by whoever writes into it: two writers
    would leave the tables of one sweep beside the figures of another. InputError with one line where
    another process holds it."""
    try:
        return files.lock_directory(output, "another process writing into it")
    except LockedError as e:
        raise InputError(f"{e}; wait for it to finish or choose another {flag}") from None


def generate_locked(args: Args) -> list[Path]:
    """generate's work, for a caller that validated `args` and holds --output's lock (claim_output)."""
    output = Path(args.output)
    previous = read_manifest(output)
    written: list[Path] = []
    try:
        write_outputs(args, output, written)
    except BaseException:
        if written:
            write_manifest(output, manifest_names(output, written), "plot_results.py", kept=previous)
        raise
    # Learning curves too: curves of another run's --runs would stand beside tables they are not of.
    names = manifest_names(output, written)
    removed, kept = remove_stale(output, {name: digest for name, digest in previous.items() if name not in names})
    for path in removed:
        print(f"note: removed {path}: the previous run into {output} wrote it, this one did not", file=sys.stderr)
    for path in kept:
        print(f"note: kept {path}: {output / MANIFEST} lists it, but not as the file a previous run wrote "
              "(edited since, or named by hand)", file=sys.stderr)  # fmt: skip
    write_manifest(output, names, "plot_results.py")
    return [*written, output / MANIFEST]


def write_outputs(args: Args, output: Path, written: list[Path]) -> None:
    """The tables, figures and reports, each recorded in `written` once it is complete."""
    provenance = read_provenance(args.provenance)
    episodes = read_episodes(args.sweeps, check=table_kinds)
    summary = summarise(select_mode(episodes, args.policy, args.null_branch), provenance)
    steps = sorted({int(r["step"]) for r in summary})
    if args.response_step is not None and args.response_step not in steps:
        raise InputError(f"--response-step {args.response_step}: the sweeps hold no checkpoint at that step "
                         f"(their steps: {', '.join(map(str, steps))})")  # fmt: skip
    for note in (short_cells_note(summary), short_configurations_note(summary)):
        if note:
            print(note, file=sys.stderr)
    if len({(r["policy"], r["null_branch"]) for r in episodes}) > 1:
        write(output / "controls.md", controls_table(summarise(episodes, provenance)), written)
    if args.provenance:
        write(output / "provenance.md", provenance_markdown(episodes, provenance), written)
    by_kind = defaultdict(list)
    for r in summary:
        by_kind[r["kind"]].append(r)
    for kind, rows in sorted(by_kind.items()):
        envs = sorted({r["env_id"] for r in rows})
        title = f"{kind.capitalize()} environments"
        write(output / f"table_{kind}.md", markdown_table(rows, envs, title=title), written)
        write(output / f"table_{kind}.tex", latex_table(rows, envs, title=title), written)
        ppo_gammas = {float(r["eval_guidance"]) for r in rows if r["variant"] == "ppo"}
        if len(ppo_gammas) > 1:
            title = f"Vanilla PPO checkpoints swept over eval guidance ({kind})"
            write(output / f"table_{kind}_ppo_sweep.md", markdown_table(rows, envs, True, title=title), written)
            write(output / f"table_{kind}_ppo_sweep.tex", latex_table(rows, envs, True, title=title), written)
        layout, cols = figures.figure_layout(kind, envs)
        variants = sorted({r["variant"] for r in rows}, key=lambda v: (variant_rank(v), v))
        for variant in variants:
            swept = {float(r["eval_guidance"]) for r in rows if r["variant"] == variant}
            low, high = PAPER_FIGURE_GAMMAS.get((kind, variant), (-math.inf, math.inf))
            inside = {g for g in swept if low <= g <= high}
            paper_tasks = all(env in PAPER_ENVS[kind] for env in envs)
            beside_paper = PAPER_FIGURE_GAMMAS.get((kind, variant)) and paper_tasks  # on the paper's y-ranges
            y_limits = figures.PAPER_DROPOUT_FIGURE_YLIM if beside_paper else None
            figure = figures.figure_for_variant(rows, envs, variant, layout, cols, gammas=inside, y_limits=y_limits)
            save_figure(figure, output / f"fig_{kind}_{variant}", written)
            if swept - inside:
                rest = sorted(swept - inside)
                title = (f"{paper_name(variant)}: the eval γ beyond the paper's figure "
                         f"({', '.join(f'{g:g}' for g in rest)}), γ = 1 for reference")  # fmt: skip
                figure = figures.figure_for_variant(
                    rows, envs, variant, layout, cols, gammas=set(rest) | {1.0}, title=title
                )
                save_figure(figure, output / f"fig_{kind}_{variant}_beyond_paper", written)
        save_figure(figures.gamma_response(rows, envs, args.response_step), output / f"gamma_response_{kind}", written)
    best = best_gamma(summary)
    write_csv(output / "best_gamma.csv", best, written)
    write(output / "best_gamma.md", simple_markdown(best), written)
    references, missing = normalisation_references(summary)
    if missing:
        left_out = "; ".join(f"{env}: {why}" for env, why in missing.items())
        print(f"note: the aggregate IQM and performance profile leave out the tasks with no reference to normalise "
              f"by ({left_out})", file=sys.stderr)  # fmt: skip
    aggregate = aggregate_iqm(summary)
    if aggregate:
        said = reference_text(references, references)
        write_csv(output / "aggregate_iqm.csv", aggregate, written)
        write(output / "aggregate_iqm.md", simple_markdown(aggregate) + f"\nScores normalised per task: {said}.\n",
              written)  # fmt: skip
        for kind in sorted({r["kind"] for r in summary if r["env_id"] in references}):
            of_kind = [r for r in summary if r["kind"] == kind]
            said = reference_text(references, {r["env_id"] for r in of_kind if r["env_id"] in references})
            intervals = figures.aggregate_intervals(aggregate_iqm(of_kind), kind, said)
            save_figure(intervals, output / f"aggregate_iqm_{kind}", written)
            profile = figures.performance_profiles(*performance_profiles(of_kind), kind=kind, reference=said)
            save_figure(profile, output / f"performance_profile_{kind}", written)
    if args.runs:
        curves, left_out = training_curves(args.runs)
        for _, run_dir, why in left_out:
            print(f"note: the learning curves leave out {run_dir}: {why}", file=sys.stderr)
        save_figure(figures.learning_curves(curves, left_out), output / "learning_curves", written)
    if args.compare_paper:
        compare_paper(summary, output, written)


def compare_paper(summary: list[dict], output: Path, written: list[Path]) -> None:
    """The agreement report, of the paper's configurations only (paper.is_paper_configuration): on the
    paper's tasks a fork or any other configuration of a variant the paper tables is left out, and named
    on stderr and in the report. Nothing is written where no swept task is the paper's."""
    paper_tasks = {env for envs in PAPER_ENVS.values() for env in envs}
    others = {(r["env_id"], r["config"]) for r in summary
              if r["env_id"] in paper_tasks and paper_rows(r["variant"]) and not is_paper_configuration(r)}  # fmt: skip
    left_out = [f"{env} `{config}`" for env, config in sorted(others)]
    named = (f"Left out, not the paper's configuration (a fork, or training arguments other than the paper's): "
             f"{'; '.join(left_out)}.\n")  # fmt: skip
    if left_out:
        print(f"note: left out of the comparison with the paper, not its configuration: {'; '.join(left_out)}",
              file=sys.stderr)  # fmt: skip
    cells = [r for r in summary if (r["env_id"], r["config"]) not in others]
    if left_out and not any(r["env_id"] in paper_tasks for r in cells):
        write(output / "compare_paper.md", f"# Against the paper\n\nNo cell compared.\n\n{named}", written)
        return
    comparison = compare_with_paper(cells)
    if comparison is None:  # no swept task is the paper's: their tables and figures are the results
        return
    tasks = task_summaries(comparison, cells)
    report = comparison_markdown(comparison, cells, tasks) + (f"\n{named}" if left_out else "")
    write_csv(output / "compare_paper.csv", comparison, written)
    write_csv(output / "compare_paper_tasks.csv", tasks, written)
    write(output / "compare_paper.md", report, written)


# --- the manifest of outputs ----------------------------------------------------------------------


def manifest_names(output: Path, paths) -> set[str]:
    return {str(Path(path).relative_to(output)) for path in paths}


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with files.one_line_errors():
        try:
            startup.ctrl_c_handled()
            written = generate(args)
        except KeyboardInterrupt:
            print("interrupted; the outputs written so far are complete files", file=sys.stderr)
            sys.exit(130)
    for path in written:
        print(path)


if __name__ == "__main__":
    main()
