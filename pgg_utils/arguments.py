"""The arguments every training script shares and the rules they obey, once for the scripts, the
sweep, the launcher and an agent's `act`. No torch, no gymnasium."""

import math
import sys
from dataclasses import dataclass, fields

import numpy as np

from pgg_utils.guidance import SCHEDULES

MAX_GUIDANCE = 1000.0
# The γ values a sweep evaluates (--gammas) unless told otherwise: the paper's, by action space.
DEFAULT_GAMMAS = {
    "discrete": (1.0, 1.5, 2.0, 5.0, 10.0, 20.0),
    "continuous": (1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.5),
}


@dataclass
class RunArgs:
    """The arguments every training script has besides its algorithm's: CleanRL's header, and where
    and how the run is recorded."""

    exp_name: str | None = None
    """the name of this experiment, what W&B and TensorBoard runs are grouped by, and part of the run directory's name; None: CleanRL's default, the script's file stem, with the variant (`ppo_pgg_discrete__pgg_g1.1`, `ppo_relu__ppo`); the run directory then holds the file stem (`ppo_pgg` for the repository's two scripts, as their runs always have)"""
    seed: int = 1
    """seed of the experiment (torch, numpy, random and the environments)"""
    torch_deterministic: bool = True
    """if toggled, `torch.use_deterministic_algorithms(True)`"""
    torch_threads: int = 1
    """torch intra-op threads; one thread is fastest for these small networks"""
    compile: bool = False
    """compile the minibatch loss and its backward with torch.compile (needs a C++ compiler): training ~1.25x faster after a one-off compile of ~20 s (~3 s from inductor's cache); the same algorithm, rounded differently (benchmarks/README.md, --compile)"""
    track: bool = False
    """if toggled, track the run with Weights and Biases (needs `pip install wandb`)"""
    wandb_project_name: str = "pgg"
    """the W&B project name"""
    wandb_entity: str | None = None
    """the W&B entity (team)"""
    output_dir: str = "runs"
    """directory under which the run directory is created"""
    run_name: str | None = None
    """run directory name, one path component; None: `{env_id}__{exp_name}__g{guidance}__p{cond_dropout}__s{seed}`, with the schedule in place of `g{guidance}` and a fork's new arguments with their values before the seed (pgg_utils/identity.py, Configuration.run_name)"""
    resume: bool = False
    """continue the run in the run directory from its last readable checkpoint (start it if it has none)"""
    overwrite: bool = False
    """replace a run directory that holds checkpoints of a finished run or of other arguments"""
    capture_video: bool = False
    """record videos of the first sub-env's episodes into `{run_dir}/videos` (needs the [video] extra and, for MuJoCo, a GL backend: MUJOCO_GL=egl or osmesa)"""
    checkpoint_interval: int = 100_000
    """save a checkpoint at the first iteration boundary past each multiple of this many steps (at least one batch, num_envs * num_steps)"""


# Arguments that change where and how a run is recorded or how fast it runs, never what it learns
# (--compile, the thread count and deterministic kernels change float rounding only).
RUN_ONLY_ARGS = frozenset(f.name for f in fields(RunArgs)) - {"seed"}


# CleanRL's flags typed from habit, by their dashed spelling (CleanRL's tyro also takes `--no_cuda`): the
# answer that points to this project's equivalent, and whether the flag is accepted (its meaning holds here).
CPU_ONLY = (
    "these scripts train on the CPU only (small MLPs on a few envs, and the tables' numbers are of CPU runs); "
    "the speed comes from the numpy rollout path (pgg_utils/fast.py), one torch thread per run and --compile "
    "(benchmarks/README.md)"
)
SAVED = "checkpoints are always saved, every --checkpoint-interval steps, in <run>/checkpoints"
NO_HUB = (
    "these scripts upload nothing to the Hugging Face Hub: the agents are the files in <run>/checkpoints "
    "(ppo_pgg_<kind>.load_checkpoint loads one; the README's 'Use a trained agent'), to share as they are"
)
CLEANRL_HABITS = {
    "--gamma": ("CleanRL's --gamma is the discount factor: here it is --discount (γ is PGG's guidance here)", False),
    "--cuda": (CPU_ONLY, False),
    "--no-cuda": (CPU_ONLY, True),
    "--save-model": (SAVED, True),
    "--no-save-model": (SAVED, False),
    "--batch-size": ("the batch size is derived: --num-envs × --num-steps", False),
    "--minibatch-size": ("the minibatch size is derived: --num-envs × --num-steps / --num-minibatches", False),
    "--num-iterations": (
        "the number of iterations is derived: ⌈--total-timesteps / (--num-envs × --num-steps)⌉",
        False,
    ),
    "--upload-model": (NO_HUB, False),
    "--no-upload-model": (NO_HUB, True),
    "--hf-entity": (NO_HUB, False),
}


def answer_cleanrl_habits(argv: list[str]) -> list[str]:
    """`argv` without the CleanRL flags whose meaning holds here (--no-cuda, --save-model), each noted in
    one line on stderr; a CleanRL flag that means something else here (--gamma) or nothing (--cuda,
    --batch-size, --num-iterations, --upload-model, --hf-entity) exits 2 with one line naming this project's
    equivalent. For a training script's tyro.cli."""
    kept = []
    for i, token in enumerate(argv):
        flag = token.split("=", 1)[0].replace("_", "-") if token.startswith("--") else None
        if flag not in CLEANRL_HABITS:
            kept.append(token)
            continue
        answer, accepted = CLEANRL_HABITS[flag]
        if not accepted or "=" in token:
            print(f"error: {token.split('=', 1)[0]}: {answer}", file=sys.stderr)
            sys.exit(2)
        print(f"note: {token}: {answer}; it changes nothing here", file=sys.stderr)
    return kept


# --- argument rules ------------------------------------------------------------------------------


def guidance_error(value: float, flag: str = "--guidance") -> str | None:
    """The one rule for a guidance strength: training's --guidance (ARGUMENT_RULES), the sweep's --gammas."""
    if not (math.isfinite(value) and 0.0 <= value <= MAX_GUIDANCE):
        return f"{flag} must be a number in [0, {MAX_GUIDANCE:g}], got {value!r}"
    return None


def acting_error(obs: np.ndarray, guidance: np.ndarray) -> str | None:
    """What an agent's `act` refuses, one line, or None: a guidance strength outside guidance_error's rule
    (`guidance` a number, or one per row of `obs`), and an observation holding a NaN or an infinity (its
    action would be NaN, or an arbitrary argmax). A few reductions: the sweep acts through `act` every step."""
    rows = 1 if obs.ndim == 1 else len(obs)
    if guidance.ndim > 0 and guidance.shape != (rows,):
        return f"guidance must be a number or one per observation ({rows}), got an array of shape {guidance.shape}"
    if error := guidance_error(float(guidance.min()), "guidance") or guidance_error(float(guidance.max()), "guidance"):
        return error  # a NaN anywhere is the minimum's
    if not np.isfinite(obs).all():
        return "the observation holds a NaN or an infinity"
    return None


def run_name_error(name: str | None, what: str = "--run-name") -> str | None:
    """A run name is one path component: it cannot leave --output-dir or name it, and it is printable
    with no space at either end (a blank or a newline would make a directory no one can type). The
    rule of the final name, whether given (--run-name) or built (`what` then says from which flags)."""
    if name is None:
        return None
    if not name.strip() or name in (".", "..") or "/" in name or "\\" in name or name != name.strip():
        return f"{what} must be one path component (no '/', not '.' or '..', no space at an end), got {name!r}"
    if not name.isprintable():
        return f"{what} must be printable (no newline or control character), got {name!r}"
    return None


def env_id_in_path(env_id: str) -> str:
    """An env id as a run name holds it: a namespaced or module-qualified id (`mymod:ns/Env-v0`) has
    each ':' and '/' replaced by '-' (`mymod-ns-Env-v0`), so that the name stays one path component;
    any other id is kept as it is."""
    return env_id.replace(":", "-").replace("/", "-")


# name -> (holds, requirement); NaN fails every comparison. Rules of arguments a script lacks are skipped.
# Every training argument has one (tests/test_extending.py), so a new flag cannot go unchecked.
ARGUMENT_RULES = {
    "learning_rate": (lambda v: 0 < v < math.inf, "a finite number > 0"),
    "discount": (lambda v: 0 <= v <= 1, "in [0, 1]"),
    "gae_lambda": (lambda v: 0 <= v <= 1, "in [0, 1]"),
    "clip_coef": (lambda v: 0 < v < math.inf, "a finite number > 0"),
    "ent_coef": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
    "vf_coef": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
    "max_grad_norm": (lambda v: 0 < v < math.inf, "a finite number > 0"),
    "target_kl": (lambda v: v is None or 0 < v < math.inf, "a finite number > 0"),
    # At 1 no row keeps its state: every ratio compares pi(a|null) with the pi_hat(a|s) that acted, and the
    # KL and clip fraction of the kept rows are of none.
    "null_bc_coef": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
    "null_bc_route": (lambda v: v in ("null", "actor"), "null or actor"),
    "cond_dropout": (lambda v: 0 <= v < 1, "in [0, 1) (at 1 no row keeps its state)"),
    "guidance": (lambda v: guidance_error(v) is None, f"a number in [0, {MAX_GUIDANCE:g}]"),
    "guidance_schedule": (lambda v: v in SCHEDULES, ", ".join(SCHEDULES)),
    "guidance_final": (lambda v: v is None or 0 <= v <= MAX_GUIDANCE, f"a number in [0, {MAX_GUIDANCE:g}]"),
    "guidance_kl_target": (lambda v: v is None or 0 < v < math.inf, "a finite number > 0"),
    "guidance_bounds": (lambda v: 0 <= v[0] <= v[1] <= MAX_GUIDANCE, f"low <= high in [0, {MAX_GUIDANCE:g}]"),
    "null_dims": (lambda v: v is None or (len(v) > 0 and len(set(v)) == len(v)), "distinct observation indices"),
    "seed": (lambda v: 0 <= v < 2**32, "in [0, 2**32 - 1] (numpy's seeds)"),
    "total_timesteps": (lambda v: v > 0, "positive"),
    "num_minibatches": (lambda v: v > 0, "positive"),
    "anneal_lr": (lambda v: isinstance(v, bool), "true or false"),
    "norm_adv": (lambda v: isinstance(v, bool), "true or false"),
    "clip_vloss": (lambda v: isinstance(v, bool), "true or false"),
    "num_envs": (lambda v: v > 0, "positive"),
    "num_steps": (lambda v: v > 0, "positive"),
    "update_epochs": (lambda v: v > 0, "positive"),
    "torch_threads": (lambda v: v > 0, "positive"),
    "obs_clip": (lambda v: 0 < v <= math.inf, "> 0"),
    "reward_clip": (lambda v: 0 < v <= math.inf, "> 0"),
}
