"""Sweep the PGG guidance strength γ on saved checkpoints, without retraining.

    python eval_gamma_sweep.py runs/ --output sweeps/all
    python eval_gamma_sweep.py runs/discrete --gammas 1 2 5 --steps 100000 500000 --workers 2
    python eval_gamma_sweep.py RUN/checkpoints/step_000500000.pt --gammas 1 2 5 --video videos/   # watch the knob

Every checkpoint under the given run directories (or roots) is evaluated at each γ for `--episodes`
episodes. A (checkpoint, γ) cell is evaluated on its own: its episodes step together, one row each
in a batch of their own, with one policy forward per step; an episode that ends keeps its row
(padded) until the whole cell is done.

Reproducibility. Episode k of every cell starts from `env.reset(seed=eval_seed + k)` and draws its
action noise from its own stream, `np.random.default_rng([eval_seed + k, 1])`: the same episode seeds
and noise for every γ and every checkpoint (common random numbers). The default eval_seed, 10_000,
keeps evaluation seeds disjoint from the training scripts' (seed + env index, i.e. small integers).

Exactness. Every policy forward of a cell has cell_rows(episodes) = max(episodes, 8) rows, from its
first step to its last, and nothing of another cell enters its batch: on one machine and software
stack a cell's rows are bit-identical whether it is swept alone, beside other γ values, in a worker
or after a resume; across machines they are statistically equal, not identical (benchmarks/README.md,
"Exactness of the sweep").

Which code evaluates. A checkpoint is evaluated by the script that trained it, as CleanRL's evaluation
takes `Agent` from the file that trained it: the repository's file the checkpoint names (the two
scripts, or a fork copied beside them), or a file given with --script of that name (a fork kept
elsewhere, a copy). A checkpoint never makes the sweep run code from anywhere else: one whose script
cannot be found, or whose `Agent` cannot load its weights, is skipped with one line (skipped.csv).
evaluated_by.csv names the file that evaluated each checkpoint and whether it is the one that trained
it (same_script: yes, no, or unknown for checkpoints from before scripts recorded their own sha1).

Configurations. A cell's seeds must be distinct runs of one training configuration: the script and
every training argument (pgg_utils.identity.config_label). Every row carries `config`, its label: the
variant, the script where it is not the repository's own, and every training argument that differs
from the script's defaults, e.g. `pgg_g1.1 learning_rate=0.002` or `pgg_g1.1 script=ppo_pgg_relu.py`,
and `config_fields`, the same as a JSON object that readers compare without parsing the label;
summaries are grouped by it, and two checkpoints of one env, configuration, seed and step are an error
naming both. Checkpoints whose model holds a NaN or an infinity are skipped, never evaluated.

Outputs (in --output, locked against a second sweep while this one runs): cells/*.csv, one per
finished (checkpoint, γ) cell, written atomically and named by the bytes of the checkpoint that were
evaluated, the γ, the settings, the evaluation stack (the mujoco, gymnasium, numpy and torch versions,
recorded in every row) and every file of code that runs in its episodes: this sweep's file (or a copy
of it), the script that evaluates the checkpoint, a custom task's module, and each module these import,
read from their import statements, wherever it lies on the path (a fork's or a task's helper module, a
package's other modules), but for installed packages and the standard library, which the stack's versions
stand for (evaluation_code, cells.imported_files). A rerun reuses a cell only if it is whole
and every row's checksum holds, so an interrupted sweep (Ctrl-C: exit status 130) loses only the cells
in flight, a damaged cell is evaluated again, and so is every cell after an edit to any of that code.
Then episodes.csv (every episode of the requested cells, sorted), summary.csv (per env, variant,
config, step and γ: mean over seeds of the per-seed mean return, and its 95% confidence interval, see
`mean_ci95`), skipped.csv, evaluated_by.csv, and written.csv: episodes.csv, summary.csv and skipped.csv with their numbers of rows and sha256, by which
plot_results.py refuses an episodes.csv that is not whole.

Returns and faults. An episode's return is the task's own: the one that gymnasium's RecordEpisodeStatistics,
which the script's make_env puts directly on gym.make's env (pgg_utils.tasks.task_env), records at its end,
whatever make_env adds around it (a reward scale); for a script whose make_env has none, the sum of make_env's
rewards, the figure its training logged (records_episodes). A checkpoint is skipped, with one line in skipped.csv
and on stderr, and the sweep goes on, where its task's spaces are not those it was trained on (pgg_utils.tasks),
or where during its episodes the task raises, or returns an observation or a reward holding a NaN or an infinity.

Changing the episodes. Copy this file, and copy into it `evaluate_cell`, the one episode loop of a cell, from
pgg_utils/evaluation.py (below the imports, with `from pgg_utils.evaluation import *` for the names it uses): the
sweep plays every episode with the `evaluate_cell` of the file that runs. Then edit it: an observation transform
goes where the loop reads `obs`, and a per-episode metric is one more entry of the dict it returns, one value per
episode, written after the sweep's columns in every cell and in episodes.csv (a name of the sweep's own columns,
or not one value per episode, is refused in one line). The copy's cells are its own: its file is part of every
cell's identity, so the original's cells are never reused by it, nor its cells by the original, even in one
--output. Every episode is played by that loop: the copy's --video films its cell's episode, with its return.

The engine lies in pgg_utils: the episode loop and the guided policy in pgg_utils/evaluation.py, the cells and
their identity in pgg_utils/cells.py, the grid, the workers and the outputs in pgg_utils/sweep.py, the videos in
pgg_utils/video.py.
"""

from pgg_utils import startup  # first: a Ctrl-C during the imports below is one line, status 130

# isort: split
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

from pgg_utils import scripts, video
from pgg_utils import sweep as engine
from pgg_utils.arguments import guidance_error
from pgg_utils.evaluation import evaluate_cell
from pgg_utils.files import InputError, one_line_errors


@dataclass
class Args:
    paths: tyro.conf.Positional[tuple[str, ...]]
    """run directories, roots to search for them, or checkpoint files"""
    output: str = "sweep"
    """output directory (cells/, episodes.csv, summary.csv); reusing it resumes a sweep"""
    gammas: tuple[float, ...] | None = None
    """eval guidance strengths; None: the paper's, discrete 1 1.5 2 5 10 20, continuous 1 1.05 ... 1.3 1.5"""
    episodes: int = 50
    """episodes per (checkpoint, γ) cell"""
    steps: tuple[int, ...] | None = None
    """only the checkpoints of these step marks (e.g. 100000 500000); None: all"""
    eval_seed: int = 10_000
    """episode k resets with seed eval_seed + k; keep it away from training seeds"""
    deterministic: bool = False
    """control: act with the argmax / mean of the guided policy instead of sampling it"""
    uniform_null: bool = False
    """control (discrete only): a uniform unconditional branch instead of the learned one, making guidance plain temperature scaling of the conditional policy"""
    workers: int = 1
    """processes that evaluate checkpoints in parallel"""
    ci: Literal["t", "bootstrap"] = "t"
    """confidence interval over per-seed means: Student t, or a percentile bootstrap"""
    bootstrap_samples: int = 10_000
    """resamples for --ci bootstrap"""
    video: str | None = None
    """instead of sweeping, record one episode of ONE checkpoint at each γ into this folder: gamma_<γ>.mp4 and side_by_side.mp4, each the sweep's cell episode --video-episode, played in its cell of --episodes episodes (needs the [video] extra); None: sweep"""
    script: tuple[str, ...] = ()
    """training scripts to evaluate with besides the repository's: a checkpoint is evaluated by the one of its training script's file name (a fork kept outside the repository, or a copy of a script); () : the repository's only"""
    video_episode: int = 0
    """with --video: the episode to record, k < --episodes: the sweep's cell episode k (its reset seed eval_seed + k, its noise, its return)"""


def check_args(args: Args) -> None:
    """Every argument, before anything is read or written; InputError with one line."""
    if not args.paths:
        raise InputError("no run directories, roots or checkpoint files given (e.g. eval_gamma_sweep.py runs/)")
    if args.gammas is not None:
        if not args.gammas:
            raise InputError("--gammas needs at least one value (leave it out for the paper's)")
        for gamma in args.gammas:
            if error := guidance_error(gamma, "--gammas"):  # the training scripts' rule
                raise InputError(error)
    if args.steps is not None and not args.steps:
        raise InputError("--steps needs at least one value (leave it out for every checkpoint)")
    if args.episodes <= 0 or args.workers <= 0 or args.bootstrap_samples <= 0:
        raise InputError("--episodes, --workers and --bootstrap-samples must be positive")
    if args.eval_seed < 0 or args.video_episode < 0:
        raise InputError(f"--eval-seed and --video-episode must be >= 0, got {args.eval_seed} and {args.video_episode}")
    if args.video is not None and args.video_episode >= args.episodes:
        raise InputError(f"--video-episode {args.video_episode} is not an episode of a cell of --episodes "
                         f"{args.episodes} (0 to {args.episodes - 1}); raise --episodes to film it")  # fmt: skip
    if not args.output:
        raise InputError("--output must name a directory")
    if error := scripts.given_script_error(args.script):
        raise InputError(error)


def sweep(args: Args) -> Path:
    """Runs (or resumes) the sweep (pgg_utils.sweep.sweep), every episode played by this file's `evaluate_cell`;
    returns the output directory."""
    check_args(args)
    return engine.sweep(args, Path(__file__), evaluate_cell)


def record_videos(args: Args) -> list[Path]:
    """--video (pgg_utils.video.record_videos), every episode played by this file's `evaluate_cell`; returns the
    files written."""
    check_args(args)
    return video.record_videos(args, evaluate_cell)


def main() -> None:
    args = tyro.cli(Args, description=__doc__)
    with one_line_errors():
        try:
            startup.ctrl_c_handled()
            if args.video is not None:
                for path in record_videos(args):
                    print(path)
                return
            sweep(args)
        except KeyboardInterrupt as e:
            print(f"interrupted: {e}" if isinstance(e, engine.SweepInterrupted) else "interrupted before any cell was evaluated",
                  file=sys.stderr)  # fmt: skip
            sys.exit(130)


if __name__ == "__main__":
    main()
