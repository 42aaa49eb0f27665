"""The sweep's engine: the grid of (checkpoint, γ) cells a sweep asks for (plan), each evaluated on its own by the
sweep's episode loop (pgg_utils.evaluation.evaluate_cell, or a copy's own) in a worker pool (evaluate_missing), written
as it finishes (pgg_utils.cells) and reused on a rerun, then the sweep's outputs: episodes.csv, summary.csv
(summary_rows), skipped.csv, evaluated_by.csv and written.csv, in an output folder locked against a second sweep
(claim_output). eval_gamma_sweep.py holds the arguments and calls `sweep`; its module docstring says what the
outputs hold."""

import sys
import time
from collections.abc import Callable
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pgg_utils import scripts
from pgg_utils.arguments import DEFAULT_GAMMAS
from pgg_utils.cells import (
    EPISODE_COLUMNS,
    EVALUATED_BY_COLUMNS,
    STACK_COLUMNS,
    Evaluation,
    cell_path,
    evaluation_of,
    evaluation_stack,
    extra_columns,
    read_cell,
    write_cell,
)
from pgg_utils.checkpoints import find_checkpoints
from pgg_utils.episodes import cell_of, check_one_run_per_seed, summarise
from pgg_utils.evaluation import EpisodeFault, GuidedPolicy, evaluate_cell, first_line, read_checkpoint
from pgg_utils.files import (
    InputError,
    LockedError,
    RuntimeFailure,
    check_writable,
    lock_directory,
    write_csv_atomic,
    write_record,
)
from pgg_utils.identity import Configuration, configuration, configuration_fields, run_of
from pgg_utils.processes import how_workers_died, start_pool, stop_pool
from pgg_utils.progress import Progress, format_duration

SUMMARY_COLUMNS = [
    "env_id", "variant", "config", "train_guidance", "cond_dropout", "step", "eval_guidance", "policy", "null_branch",
    "n_seeds", "n_episodes", "mean", "ci95", "ci_low", "ci_high", "ci_method", "seed_means",
]  # fmt: skip


@dataclass(frozen=True)
class Job:
    checkpoint: Path
    gamma: float
    settings: tuple  # (episodes, eval_seed, deterministic, uniform_null)
    stack: tuple  # evaluation_stack() of the sweep
    evaluation: Evaluation  # the script that evaluates the checkpoint and the fingerprint of what computes the cell
    loop: Callable  # the sweep's episode loop: pgg_utils.evaluation.evaluate_cell, or a copy's own


@dataclass
class JobResult:
    job: Job
    digest: str | None  # sha1 of the checkpoint bytes that were evaluated
    rows: list[dict]
    env_steps: int
    error: str | None


def settings_of(args) -> tuple:
    return (args.episodes, args.eval_seed, args.deterministic, args.uniform_null)


def run_job(job: Job) -> JobResult:
    """Evaluates one cell. The checkpoint is read once; the rows, and the digest that names their
    cell, come from those bytes."""
    torch.set_num_threads(1)
    episodes, eval_seed, deterministic, uniform_null = job.settings
    try:
        digest, ckpt = read_checkpoint(job.checkpoint)
        agent, module, _ = scripts.load_agent(ckpt, job.checkpoint, (job.evaluation.script,))
        fields = configuration_fields(ckpt)
    except Exception as e:
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {e}")
    policy = GuidedPolicy(agent, ckpt, uniform_null, module)
    try:
        columns = job.loop(policy, ckpt, job.gamma, episodes, eval_seed, deterministic)
    except EpisodeFault as e:  # the task's fault: none of the checkpoint's cells is tabled, the sweep goes on
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {e}; none of its cells is tabled")
    except Exception as e:  # a fork's agent or make_env failing mid-episode: the same
        return JobResult(job, None, [], 0, f"{job.checkpoint}: at γ = {job.gamma:g}: {first_line(e)}; "
                                           "none of its cells is tabled")  # fmt: skip
    returns, lengths = columns.pop("return"), columns.pop("length")
    if error := added_columns_error(columns, episodes):
        return JobResult(job, None, [], 0, f"{job.checkpoint}: {error}")
    if not np.isfinite(returns).all():
        bad = np.flatnonzero(~np.isfinite(returns))
        return JobResult(job, None, [], 0, f"{job.checkpoint}: episode {bad[0]} at γ = {job.gamma:g} returned "
                                           f"{returns[bad[0]]} (a non-finite reward); none of its cells is tabled")  # fmt: skip
    common = {
        "env_id": ckpt["env_id"],
        "variant": fields["variant"],
        "config": fields["config"],
        "config_fields": fields["config_fields"],
        "run": run_of(ckpt, job.checkpoint),
        "seed": ckpt["args"]["seed"],
        "train_guidance": fields["train_guidance"],
        "cond_dropout": fields["cond_dropout"],
        "step": ckpt["step_mark"],
        "global_step": ckpt["global_step"],
        "eval_guidance": job.gamma,
        "policy": "deterministic" if deterministic else "sample",
        "null_branch": "uniform" if uniform_null else "bc" if ckpt.get("null_fit") else "learned",
        **dict(zip(STACK_COLUMNS, job.stack)),
        "action_space": ckpt["action_space"],
    }
    rows = [
        {**common, "episode": k, "episode_seed": eval_seed + k, "return": float(returns[k]), "length": int(lengths[k]),
         **{column: values[k] for column, values in columns.items()}}
        for k in range(episodes)
    ]  # fmt: skip
    return JobResult(job, digest, rows, int(lengths.sum()), None)


def added_columns_error(columns: dict, episodes: int) -> str | None:
    """One line where a per-episode column that evaluate_cell adds cannot be written: a name of the
    sweep's own columns, or not one value per episode."""
    for column, values in columns.items():
        if column in EPISODE_COLUMNS or column == "checksum" or not column.isidentifier():
            return (f"evaluate_cell's column {column!r} is refused: per-episode columns it adds need a name of "
                    "their own (letters, digits, underscores; none of the sweep's columns)")  # fmt: skip
        if np.shape(values) != (episodes,):
            return f"evaluate_cell's column {column!r} has shape {np.shape(values)}, not one value per episode ({episodes})"
    return None


GROUP_COLUMNS = SUMMARY_COLUMNS[:9]  # a summary row per (env, variant, config, ..., γ, policy, null branch)


def summary_rows(rows: list[dict], method: str = "t", bootstrap_samples: int = 10_000) -> list[dict]:
    """summary.csv: one row per (env, variant, config, step, γ, policy, null branch), the statistics over seeds of
    the per-seed mean episodic return (episodes.summarise) rounded to 4 places. A seed must be one run: InputError
    where two runs (the `run` column) give the same seed of one group, or one run gives the same episode twice."""
    check_one_run_per_seed(rows, configuration, cell_of)
    group_of = lambda row: tuple(configuration(row)[2] if c == "config" else str(row[c]) for c in GROUP_COLUMNS)
    order = lambda k: (k[0], k[1], k[2], int(k[5]), float(k[6]), k[7], k[8])
    return [{
        **dict(zip(GROUP_COLUMNS, cell["key"])),
        "n_seeds": len(cell["seed_means"]), "n_episodes": cell["n_episodes"],
        "mean": round(cell["mean"], 4), "ci95": round(cell["ci95"], 4), "ci_low": round(cell["ci_low"], 4),
        "ci_high": round(cell["ci_high"], 4), "ci_method": method,
        "seed_means": ";".join(f"{m:.4f}" for m in cell["seed_means"]),
    } for cell in summarise(rows, group_of, order, method, bootstrap_samples)]  # fmt: skip


def episode_sort_key(row: dict):
    return (row["env_id"], row["variant"], configuration(row)[2], row["run"], int(row["step"]), float(row["eval_guidance"]),
            row["policy"], row["null_branch"], int(row["episode"]))  # fmt: skip


# --- the sweep -----------------------------------------------------------------------------------------


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep; its message says how many of the sweep's cells are on disk."""


def claim_output(output: Path):
    """Creates the output directory, checks that it and cells/ are writable (os.replace needs that),
    and takes its lock (files.lock_directory: held until the returned file is closed or its holder
    dies). InputError with one line if it cannot be written or another sweep holds it."""
    try:
        check_writable(output, output / "cells")
        return lock_directory(output, "another sweep")
    except LockedError as e:
        raise InputError(f"{e}; wait for it to finish or choose another --output") from None
    except OSError as e:
        raise InputError(f"cannot write to {output}: {e.strerror or e}") from None


class WorkerDied(RuntimeFailure):
    """A worker ended while the sweep ran (the kernel's OOM killer sends SIGKILL); one line."""


def plan(args, checkpoints: list[Path], output: Path, stack: tuple, skipped: list[str], sweeper: Path):
    """({(checkpoint, γ): cell path} of every cell the sweep asks for, {checkpoint: config label},
    {checkpoint: Evaluation}). Reads each checkpoint once; unreadable ones, those with non-finite models
    and those whose script cannot be found or load them go to `skipped`. InputError if two checkpoints
    are the same experiment, seed and step (two runs that would count as one seed). `sweeper`: the sweep's file,
    part of each cell's code digest (cells.evaluation_code)."""
    settings, cells, experiments, labels, evaluations = settings_of(args), {}, {}, {}, {}
    given, tasks = tuple(Path(path).resolve() for path in args.script), {}
    for checkpoint in checkpoints:
        try:
            digest, ckpt = read_checkpoint(checkpoint)
            evaluation = evaluation_of(checkpoint, ckpt, given, tasks, sweeper)
            config = Configuration.of_checkpoint(ckpt)
            identity = (*config.key, ckpt["args"]["seed"], ckpt["step_mark"])  # its pooling key, seed and step
            kind = ckpt["action_space"]
        except ValueError as e:  # unreadable, not a checkpoint of these scripts, non-finite, no script or task
            skipped.append(f"{checkpoint}: {e}")
            continue
        except Exception as e:
            skipped.append(f"{checkpoint}: not a PGG checkpoint ({type(e).__name__}: {e})")
            continue
        if args.uniform_null and kind != "discrete":  # once per checkpoint, not once per cell
            skipped.append(f"{checkpoint}: --uniform-null applies to discrete checkpoints only")
            continue
        other = experiments.setdefault(identity, checkpoint)
        if other != checkpoint:
            raise InputError(
                f"{other} and {checkpoint} are two runs of one experiment ({ckpt['env_id']}, {config.label!r}, seed "
                f"{ckpt['args']['seed']}, step {ckpt['step_mark']}) and would count as one seed; sweep them separately "
                "or remove one"
            )
        labels[checkpoint], evaluations[checkpoint] = config.label, evaluation
        for gamma in dict.fromkeys(args.gammas if args.gammas is not None else DEFAULT_GAMMAS[kind]):
            cells[(checkpoint, gamma)] = cell_path(output, checkpoint, gamma, settings, digest, stack,
                                                   evaluation.evaluator)  # fmt: skip
    return cells, labels, evaluations


def sweep(args, sweeper: Path, loop: Callable = evaluate_cell) -> Path:
    """Runs (or resumes) the sweep of `args` (eval_gamma_sweep.Args, checked), each cell's episodes played by `loop`
    (evaluate_cell, or a copy's own); `sweeper` is the file of the sweep that runs (eval_gamma_sweep.py or a copy),
    part of every cell's identity with all it imports (cells.evaluation_code). Returns the output directory."""
    output, skipped = Path(args.output), []
    checkpoints = find_checkpoints(args.paths, args.steps, skipped)
    lock = claim_output(output)
    threads = torch.get_num_threads()
    try:
        return sweep_locked(args, output, checkpoints, skipped, sweeper, loop)
    finally:
        torch.set_num_threads(threads)  # run_job sets one thread per process
        lock.close()


def sweep_locked(
    args, output: Path, checkpoints: list[Path], skipped: list[str], sweeper: Path, loop: Callable
) -> Path:
    stack = evaluation_stack()
    cells, labels, evaluations = plan(args, checkpoints, output, stack, skipped, sweeper)
    finished = {}  # (checkpoint, γ) -> its rows, as read back from its cell file or written to it
    try:
        for cell, path in cells.items():
            if path.exists():
                try:
                    finished[cell] = read_cell(path, args.episodes)
                except ValueError as e:
                    print(f"re-evaluating {path}: {e}", file=sys.stderr)
        print(f"{len(checkpoints)} checkpoints, {len(cells)} cells, {len(finished)} already done", file=sys.stderr)
        withheld = evaluate_missing(args, output, stack, cells, finished, skipped, evaluations, loop)
        rows, added = [], {}
        for (checkpoint, _), cell_rows in finished.items():
            if checkpoint not in withheld:
                added.setdefault(tuple(extra_columns(cell_rows[0])), checkpoint)
                # The label of today's rule: a cell written before the rule changed keeps its numbers but
                # must not split its run from the cells written after.
                rows.extend({**row, "config": labels[checkpoint]} for row in cell_rows)
        if len(added) > 1:
            raise InputError(f"the cells carry different added columns ({' and '.join(map(str, added))}); "
                             "evaluate_cell must add the same per-episode columns to every cell")  # fmt: skip
        columns = [*EPISODE_COLUMNS, *next(iter(added), ())]
        rows = [{column: row[column] for column in columns} for row in rows]
        rows.sort(key=episode_sort_key)
        summary = summary_rows(rows, args.ci, args.bootstrap_samples)
        write_csv_atomic(output / "episodes.csv", columns, rows)
        write_csv_atomic(output / "summary.csv", SUMMARY_COLUMNS, summary)
        write_csv_atomic(output / "skipped.csv", ["reason"], [{"reason": s} for s in skipped])
        evaluated = [evaluations[c].record | {"config": labels[c]} for c in sorted(evaluations) if c not in withheld]
        write_csv_atomic(output / "evaluated_by.csv", EVALUATED_BY_COLUMNS, evaluated)
        # What the sweep wrote, by rows and digest: the tables refuse an episodes.csv that is not (plot_results).
        write_record(output, {"episodes.csv": len(rows), "summary.csv": len(summary), "skipped.csv": len(skipped)},
                     "eval_gamma_sweep.py")  # fmt: skip
    except KeyboardInterrupt:
        raise SweepInterrupted(
            f"{len(finished)} of the sweep's {len(cells)} cells are finished in {output / 'cells'}; "
            "rerun the same command to evaluate the rest"
        ) from None
    except WorkerDied as e:
        raise WorkerDied(f"{e}; {len(finished)} of the sweep's {len(cells)} cells are finished in {output / 'cells'}: "
                         "rerun the same command to evaluate the rest") from None  # fmt: skip
    for reason in skipped:
        print(f"skipped {reason}", file=sys.stderr)
    for run, script in sorted({(r["run"], r["evaluated_by"]) for r in evaluated if r["same_script"] == "no"}):
        print(f"note: {run} was evaluated by {script}, which differs from the file that trained it "
              f"({output / 'evaluated_by.csv'})", file=sys.stderr)  # fmt: skip
    listed = f"; skipped {len(skipped)} checkpoint(s), listed in {output / 'skipped.csv'}" if skipped else ""
    wrote = f"{output / 'episodes.csv'} ({len(rows)} episodes), {output / 'summary.csv'} ({len(summary)} rows)"
    print(f"wrote {wrote}{listed}")
    if not rows:
        raise InputError("no checkpoint could be evaluated")
    return output


def evaluate_missing(args, output: Path, stack: tuple, cells: dict, finished: dict, skipped: list[str],
                     evaluations: dict, loop: Callable) -> set[Path]:  # fmt: skip
    """Evaluates the cells not in `finished`, writing each as it finishes and adding its rows to
    `finished`; returns the checkpoints none of whose cells may be reported, each said in `skipped`: those
    of a cell that failed, and those whose bytes changed since `cells` was planned."""
    settings = settings_of(args)
    missing = [cell for cell in cells if cell not in finished]
    jobs = [Job(checkpoint, gamma, settings, stack, evaluations[checkpoint], loop) for checkpoint, gamma in missing]
    if not jobs:
        return set()
    progress = Progress(label="sweep", total=len(jobs), unit="cells", interval=0, stream=sys.stderr)
    handled, env_steps, start, failed, changed, pool, broken = 0, 0, time.time(), {}, set(), None, False
    try:
        if args.workers > 1 and len(jobs) > 1:
            pool, futures, processes = start_pool(min(args.workers, len(jobs)), run_job, jobs)
            results = (f.result() for f in as_completed(futures) if not isinstance(f.exception(), BrokenProcessPool))
        else:
            results = map(run_job, jobs)
        for result in results:
            job, handled = result.job, handled + 1
            if result.error:  # none of the checkpoint's cells is reported: its rows would be partial
                failed.setdefault(job.checkpoint, result.error)
            else:
                # Named by the bytes that were evaluated. A checkpoint rewritten since the plan keeps its new
                # cell for a later sweep; this sweep reports none of its cells (they could mix two files).
                path = cell_path(
                    output, job.checkpoint, job.gamma, settings, result.digest, stack, job.evaluation.evaluator
                )
                rows = write_cell(path, result.rows)
                if path == cells[(job.checkpoint, job.gamma)]:
                    finished[(job.checkpoint, job.gamma)] = rows
                else:
                    changed.add(job.checkpoint)
                env_steps += result.env_steps
            elapsed = time.time() - start
            rate = env_steps / max(elapsed, 1e-9)
            progress.update(handled, f"{rate:,.0f} env steps/s  elapsed {format_duration(elapsed)}")
        broken = pool is not None and handled < len(jobs)  # the failed futures: BrokenProcessPool, all of them
    finally:
        progress.close()
        if pool:
            stop_pool(pool, processes)
    if broken:
        raise WorkerDied(f"a sweep worker died ({how_workers_died(processes)}) and the cells in flight with it")
    skipped.extend(failed.values())
    rewritten = sorted(changed - failed.keys())
    skipped.extend(f"{c}: rewritten during the sweep; rerun the sweep to evaluate its new contents" for c in rewritten)
    return failed.keys() | changed
