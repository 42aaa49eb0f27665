"""A training run, once for both scripts: `Run` prepares its directory by the overwrite and resume
rules, locked while it trains, starts or resumes it, writes its checkpoints and logs; `launch` is a
script's `main` after parsing (`launch_from_command_line`, with it). The checks before it (checks.py),
the checkpoint format (checkpoints.py) and the RNG and env state a checkpoint holds (training_state.py) live by
job. The run directory's records are here too: which files a fresh start may replace, args.json, and the rule
that it agrees with the checkpoints."""

import json
import math
import os
import re
import sys
import threading
import traceback
from collections import deque
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from pgg_utils import scripts
from pgg_utils.arguments import RUN_ONLY_ARGS, answer_cleanrl_habits
from pgg_utils.checkpoints import (
    CHECKPOINT_FORMAT_VERSION,
    CheckpointError,
    checkpoint_bytes,
    checkpoint_marks,
    checkpoint_path,
    checkpoint_step,
    last_readable,
    latest_checkpoint,
    machine,
    misnamed_checkpoint,
    misnamed_checkpoints,
    non_finite,
    package_versions,
)
from pgg_utils.checks import argument_error
from pgg_utils.files import LockedError, exit_status, lock_directory, write_atomic
from pgg_utils.identity import Configuration
from pgg_utils.policy import PathError
from pgg_utils.progress import Progress
from pgg_utils.startup import ctrl_c_handled
from pgg_utils.training_state import restore_env_state, set_rng_state

# --- the run directory's records ------------------------------------------------------------------

# What else the training scripts write into a run directory: TensorBoard's events, and RecordVideo's
# videos under videos/ (a resumed run's in videos/from_step_<step>/).
EVENTS_GLOB = "events.out.tfevents.*"
VIDEO_GLOBS = ("rl-video-episode-*.mp4", "from_step_*/rl-video-episode-*.mp4")


class RunDirError(Exception):
    """A run directory this run must not write to; the message is one line that says what to do."""


class NonFiniteError(Exception):
    """Training produced a NaN or an infinity; the message is one line naming the iteration."""


def project_files(run_dir: Path, checkpoints: bool) -> list[Path]:
    """The files in a run directory that a fresh start replaces, all written by the training scripts:
    TensorBoard's events and RecordVideo's videos, and with `checkpoints` (--overwrite) the checkpoints
    and those set aside as unreadable. Anything else there, a user's notes or videos, is never deleted."""
    run_dir = Path(run_dir)
    found = [*run_dir.glob(EVENTS_GLOB), *(p for glob in VIDEO_GLOBS for p in (run_dir / "videos").glob(glob))]
    if checkpoints:
        for path in (run_dir / "checkpoints").glob("step_*.pt*"):
            name = path.name.split(".pt", 1)
            if checkpoint_step(name[0] + ".pt") is not None and re.fullmatch(r"(\.unreadable(\.\d+)?)?", name[1]):
                found.append(path)
    return sorted(p for p in found if p.is_file())


def unused_name(path: Path) -> Path:
    """`path`, or `path.1`, `path.2`, ...: the first that does not exist."""
    candidate, n = path, 0
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.{n}")
    return candidate


def as_json(values: dict) -> dict:
    """Arguments as args.json holds them (tuples as lists), so that the two records compare."""
    return json.loads(json.dumps(values))


def read_args_json(run_dir: Path) -> dict | None:
    """The arguments a run directory's args.json records; None where it has none. ValueError (one line)
    for a file that is not a JSON object."""
    path = Path(run_dir) / "args.json"
    if not path.exists():
        return None
    try:
        recorded = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path} is not a run's arguments ({type(e).__name__}: {e})") from None
    if not isinstance(recorded, dict):
        raise ValueError(f"{path} is not a run's arguments (not a JSON object)")  # noqa: TRY004 (this module's one-line errors)
    return recorded


def record_error(run_dir: Path, ckpt: dict | None = None) -> str | None:
    """Why a run's two records disagree, its args.json and its last readable checkpoint (`ckpt`, read by
    the caller; None: the directory's last readable one), or None. The training arguments both name
    must be equal: an edited args.json is never believed over the checkpoints, nor used alone."""
    try:
        recorded = read_args_json(run_dir)
    except ValueError as e:
        return str(e)
    if recorded is None:
        return None
    if ckpt is None:
        ckpt = last_readable(run_dir)[1]
    if ckpt is None:
        return None
    saved = as_json(ckpt.get("args", {}))
    differing = [f"{name} {recorded[name]!r} (checkpoints: {saved[name]!r})" for name in sorted(recorded.keys() & saved.keys())
                 if name not in RUN_ONLY_ARGS and recorded[name] != saved[name]]  # fmt: skip
    if differing:
        return f"{Path(run_dir) / 'args.json'} disagrees with the run's checkpoints: {', '.join(differing)}"
    return None


class Run:
    """One training run's directory, locked while this process trains there, and its checkpoints.

    `Run.prepare` applies the rules: a directory that holds checkpoints is only continued (--resume,
    same training arguments, from its last readable checkpoint) or replaced (--overwrite), and every
    check runs before anything is deleted. A finished run is left as it is."""

    def __init__(self, args, kind: str, script: Path):
        self.kind, self.script = kind, Path(script)
        self.config = Configuration.of_run(script, kind, args)
        self.dir = Path(args.output_dir) / (args.run_name or self.config.run_name)
        # --exp-name's default (Configuration.experiment), resolved once for every record and for W&B
        self.args = replace(args, exp_name=self.config.experiment)
        # The arguments the run starts with, its configuration, as args.json and every checkpoint record them: a
        # script that changes its args while training (an entropy schedule) keeps the changes in the resume state.
        self.arguments = self.recorded_arguments()
        self.lock = None
        self.resume_from: Path | None = None
        self.finished = False
        self.loaded: dict | None = None  # the checkpoint check_continuable read, kept for the resume
        self.notes: list[str] = []
        self.code = self.machine = None
        self.recent_returns = deque(maxlen=20)
        self.progress: Progress | None = None
        self.writer = None

    @classmethod
    def prepare(cls, args, kind: str, script: Path) -> "Run":
        """Creates and locks the run directory and writes args.json. Raises RunDirError (one line) or
        OSError (not writable)."""
        run = cls(args, kind, script)
        run.code, run.machine = scripts.code_revision(run.script), machine()
        run.dir.mkdir(parents=True, exist_ok=True)
        try:
            run.lock = lock_directory(run.dir)
        except LockedError as e:
            raise RunDirError(f"{e}; wait for it or stop it") from None
        try:
            run.apply_rules()
        except BaseException:
            run.close()
            raise
        return run

    def apply_rules(self) -> None:
        """Continues, refuses or starts the run; removes only files the training scripts wrote
        (project_files), and those only where a fresh start replaces them: with --overwrite, or with
        --resume where no checkpoint was reached (the same run, by its args.json, starts again)."""
        args = self.args
        latest, unreadable = self.last_readable_checkpoint() if not args.overwrite else (None, [])
        if not args.overwrite and (error := record_error(self.dir, self.loaded if latest else None)):
            raise RunDirError(
                self.foreign_checkpoint(latest) or f"{error}: restore it, or pass --overwrite to start over"
            )
        if latest is not None:
            self.check_continuable(latest)
        elif unreadable and not args.resume:
            raise RunDirError(f"cannot read {unreadable[0][0]} ({unreadable[0][1]}): pass --resume to continue from the "
                              "last readable checkpoint (it is kept, set aside), or --overwrite to start over")  # fmt: skip
        fresh = not (args.resume and latest is not None)
        earlier = project_files(self.dir, checkpoints=args.overwrite) if fresh else []
        if earlier and not args.overwrite:
            self.check_restartable(earlier)
        # Every check has passed: only now is anything renamed or deleted.
        self.notes += [misnamed_checkpoint(path) for path in misnamed_checkpoints(self.dir)]
        for path, why in unreadable:
            aside = unused_name(path.with_name(path.name + ".unreadable"))
            os.replace(path, aside)
            self.notes.append(f"set aside {aside.name}: {why}")
        for stale in (self.dir / "checkpoints").glob("step_*.pt.tmp"):  # a write that a kill cut short
            if checkpoint_step(stale.with_suffix("")) is not None:
                stale.unlink()
        if not fresh and checkpoint_path(self.dir, args.total_timesteps).exists():
            self.finished = True  # nothing to train, and nothing of it to touch
            return
        if not fresh:
            self.resume_from = latest
        for path in earlier:  # a fresh start; unreadable checkpoints set aside stay, unless --overwrite
            path.unlink()
        for folder in sorted({path.parent for path in earlier}, key=lambda f: -len(f.parts)):
            if folder != self.dir and not any(folder.iterdir()):  # emptied of what the scripts wrote
                folder.rmdir()
        write_atomic(self.dir / "args.json", json.dumps(self.arguments, indent=2))

    def recorded_arguments(self) -> dict:
        """The arguments as they are now, as args.json and the checkpoints record them: --output-dir relative to the
        run directory, so that no record holds a folder of the machine that trained it."""
        return {**asdict(self.args), "output_dir": os.path.relpath(self.args.output_dir, self.dir)}

    def check_restartable(self, earlier: list[Path]) -> None:
        """Raises RunDirError unless a fresh start without --overwrite may replace `earlier`, the events and
        videos of a start that reached no checkpoint: only with --resume, and only that same run's."""
        what = ", ".join(sorted({"TensorBoard events" if p.name.startswith("events.") else "videos" for p in earlier}))
        if not self.args.resume:
            raise RunDirError(f"{self.dir} holds {what} of an earlier start that reached no checkpoint: pass --resume "
                              "to start that run again in their place, or --overwrite, or choose another --run-name")  # fmt: skip
        recorded = read_args_json(self.dir)
        if recorded is None:
            raise RunDirError(f"{self.dir} holds {what} but no args.json to tell whose: pass --overwrite to replace "
                              "them, or choose another --run-name")  # fmt: skip
        if differing := self.differing(recorded):
            raise RunDirError(f"{self.dir} holds {what} of a run with other arguments ({', '.join(differing)}): "
                              "choose another --run-name, or pass --overwrite to replace them")  # fmt: skip

    def foreign_checkpoint(self, latest: Path | None) -> str | None:
        """Why `latest`, which disagrees with args.json, is the odd one out where args.json holds this command's own
        training arguments: a checkpoint of another run copied in (one line naming it, not args.json), or None."""
        try:
            recorded = read_args_json(self.dir)
        except ValueError:
            return None
        if latest is None or recorded is None or self.differing(recorded):
            return None
        theirs = ", ".join(self.differing(self.loaded.get("args", {})))
        return (f"{latest} is not this run's checkpoint: it was written by run {self.loaded.get('run', '?')} "
                f"({theirs}: as recorded -> as {self.dir / 'args.json'} and this command have it); move it out of "
                f"{latest.parent}, or pass --overwrite to start over")  # fmt: skip

    def last_readable_checkpoint(self) -> tuple[Path | None, list[tuple[Path, str]]]:
        """(the last checkpoint that loads, [(each later one that does not, why)]) (last_readable). Reads,
        renames nothing. The loaded dict is kept for the resume."""
        path, self.loaded, unreadable = last_readable(self.dir)
        return path, unreadable

    def check_continuable(self, latest: Path) -> None:
        """Raises RunDirError unless this run may continue the one whose last readable checkpoint is
        `latest` (with --resume, unreadable ones after it are set aside, kept, by apply_rules)."""
        args, ckpt = self.args, self.loaded
        if not args.resume and latest != latest_checkpoint(self.dir):
            raise RunDirError(f"cannot read {latest_checkpoint(self.dir)}: pass --resume to continue from the last "
                              f"readable checkpoint ({latest.name}; the others are kept, set aside), or --overwrite")  # fmt: skip
        if bad := non_finite(ckpt["model"]):
            raise RunDirError(f"{latest} holds non-finite weights ({', '.join(bad[:3])}): the run diverged, and continuing "
                              "it would diverge again; choose another --run-name, or pass --overwrite")  # fmt: skip
        trained_by = Configuration.of_checkpoint(ckpt).script
        if Path(trained_by).name != self.script.name:
            raise RunDirError(f"{self.dir} holds a run that {trained_by} trained, not {self.script.name}: continue it "
                              "with its own script, or choose another --run-name, or pass --overwrite")  # fmt: skip
        if differing := self.differing(ckpt.get("args", {})):
            raise RunDirError(
                f"{self.dir} holds a run with other arguments ({', '.join(differing)}): "
                "choose another --run-name, or pass --overwrite to replace it"
            )
        trained_sha1 = ckpt.get("code", {}).get("script_sha1")
        if args.resume and trained_sha1 and trained_sha1 != self.code["script_sha1"]:
            self.notes.append(f"{self.script.name} has changed since {latest.name} was written (sha1 {trained_sha1[:10]} "
                              f"-> {self.code['script_sha1'][:10]}): the checkpoints it writes record the new code")  # fmt: skip
        if not args.resume:
            finished = checkpoint_path(self.dir, args.total_timesteps).exists()
            state = "a finished run" if finished else f"an unfinished run (last checkpoint {latest.name})"
            how = "" if finished else "pass --resume to continue it, or "
            raise RunDirError(f"{self.dir} holds {state}: {how}pass --overwrite to train it again from scratch")
        if "resume" not in ckpt:
            raise RunDirError(f"{latest} predates resumable checkpoints: pass --overwrite to start over")

    def differing(self, recorded: dict) -> list[str]:
        """The training arguments in which `recorded` (a checkpoint's or args.json's) differ from this run's
        (Configuration.differing)."""
        theirs = Configuration(self.kind, self.config.script, as_json(recorded))
        ours = Configuration(self.kind, self.config.script, as_json(self.arguments))
        return theirs.differing(ours, as_json(asdict(type(self.args)())))

    def close(self) -> None:
        if self.progress is not None:
            self.progress.close()
        if self.writer is not None:
            try:
                self.writer.close()
            except OSError:  # a full disk, already reported by the write that met it
                pass
            if self.args.track:
                import wandb

                wandb.finish()
            self.writer = None
        if self.lock is not None:
            self.lock.close()
            self.lock = None

    # --- during training ---

    def checkpoint_to_resume(self) -> dict | None:
        """The checkpoint this run continues from (--resume), or None for a fresh start."""
        if self.resume_from is None:
            return None
        print(f"resuming from {self.resume_from}", flush=True)
        return self.loaded

    def open_writer(self, resumed: dict | None):
        """TensorBoard's writer (and W&B's run with --track). Events written after the checkpoint by
        the run that stopped are dropped by TensorBoard's readers."""
        from torch.utils.tensorboard import SummaryWriter

        args = self.args
        if args.track:
            import wandb

            wandb.init(project=args.wandb_project_name, entity=args.wandb_entity, sync_tensorboard=True,
                       config=asdict(args), name=self.dir.name, save_code=True)  # fmt: skip
        threading.excepthook = quiet_event_writer_thread
        self.writer = SummaryWriter(str(self.dir), purge_step=resumed["global_step"] + 1 if resumed else None)
        self.writer.add_text(
            "hyperparameters",
            "|param|value|\n|-|-|\n{}".format("\n".join(f"|{key}|{value}|" for key, value in asdict(args).items())),
        )
        return self.writer

    def video_dir(self, resumed: dict | None) -> Path | None:
        """Where --capture-video records; a resumed run records into a folder of its own, as
        RecordVideo numbers episodes from 0 again."""
        if not self.args.capture_video:
            return None
        return self.dir / "videos" / (f"from_step_{resumed['global_step']}" if resumed else "")

    def restore(self, resumed: dict, envs) -> tuple[int, int, np.ndarray | None, np.ndarray | None]:
        """(next iteration, global step, next obs, next done) of the resumed run, its sub-envs and
        RNGs restored. The observation is None for a task whose own state a checkpoint cannot hold:
        the caller starts fresh episodes, a statistically equal run."""
        state = resumed["resume"]
        for name, value in state.get("changed_arguments", {}).items():  # as the script had changed them (save)
            setattr(self.args, name, value)
        restore_env_state(envs, state["envs"])
        next_obs = next_done = None
        if all(sub_env["complete"] for sub_env in state["envs"]):
            next_obs, next_done = state["next_obs"].numpy().copy(), state["next_done"].numpy().copy()
        set_rng_state(state["rng"])
        return state["iteration"] + 1, resumed["global_step"], next_obs, next_done

    def start_or_resume(self, resumed: dict | None, envs, observe, agent, optimizer) -> tuple:
        """(first iteration, global step, next obs, next done): the sub-envs reset with the run's seed, the first
        observation as `observe` gives it to the actor; with `resumed`, the agent (in place), the optimizer, the
        sub-envs and the RNGs as that checkpoint left them."""
        raw_obs, _ = envs.reset(seed=self.args.seed)
        next_obs, next_done = observe(raw_obs), np.zeros(self.args.num_envs, dtype=np.float32)
        if resumed is None:
            return 1, 0, next_obs, next_done
        agent.load_state_dict(resumed["model"])  # in place, into the optimizer's flat buffer
        optimizer.load_state_dict(resumed["resume"]["optimizer"])
        first_iteration, global_step, next_obs, next_done = self.restore(resumed, envs)
        if next_obs is None:  # a task whose own state a checkpoint cannot hold: fresh episodes
            raw_obs, _ = envs.reset()  # from the restored RNGs, not another seed's episodes
            next_obs, next_done = observe(raw_obs), np.zeros(self.args.num_envs, dtype=np.float32)
        return first_iteration, global_step, next_obs, next_done

    def start_progress(self, global_step: int, batch_size: int, num_iterations: int) -> deque:
        """Starts the progress display; returns the checkpoint marks still ahead of `global_step`."""
        self.progress = Progress("training", num_iterations * batch_size, global_step, unit="steps")
        marks = checkpoint_marks(self.args.total_timesteps, self.args.checkpoint_interval, batch_size)
        return deque(m for m in marks if m > global_step)

    def on_episode(self, episodic_return: float, episodic_length: int, step: int) -> None:
        self.recent_returns.append(episodic_return)
        self.writer.add_scalar("charts/episodic_return", episodic_return, step)
        self.writer.add_scalar("charts/episodic_length", episodic_length, step)

    def report(self, global_step: int, iteration: int, stats: dict, weights: torch.Tensor) -> float:
        """Updates the progress display; returns this process's SPS. NonFiniteError where a loss or
        a weight of this iteration is not finite: the run stops, its earlier checkpoints kept."""
        bad = [key for key, value in stats.items() if key.startswith("losses/") and key != "losses/explained_variance"
               and not math.isfinite(value)]  # fmt: skip
        if bad or not torch.isfinite(weights).all():
            what = f"non-finite {', '.join(bad)}" if bad else "non-finite weights"
            latest = latest_checkpoint(self.dir)
            kept = f"checkpoints up to {latest.name} are kept" if latest else "no checkpoint was written"
            raise NonFiniteError(f"iteration {iteration} (global step {global_step:,}): {what}; {kept}")
        sps = self.progress.rate(global_step)
        mean = f"{np.mean(self.recent_returns):.1f}" if self.recent_returns else "-"
        self.progress.update(global_step, f"{int(sps):,} SPS  return(last 20) {mean}")
        return int(sps)

    def save(self, mark: int, global_step: int, model: dict, shapes: dict, resume: dict) -> None:
        """Writes the checkpoint of `mark`: self-contained, pickle-free (proven by loading it back) and
        atomic. `shapes`: the script's own fields (its action space and sizes). It records the arguments the run
        started with; those the script has changed since are resume state (`changed_arguments`), restored by a
        resume, so that one run is one configuration and continues as it would have."""
        changed = {name: value for name, value in self.recorded_arguments().items() if value != self.arguments[name]}
        if changed:
            resume = {**resume, "changed_arguments": changed}
        payload = {
            "format_version": CHECKPOINT_FORMAT_VERSION,
            "script": self.script.stem,
            "script_path": scripts.recorded_path(self.script),
            "action_space": self.kind,
            "env_id": self.args.env_id,
            **shapes,
            "global_step": int(global_step),
            "step_mark": int(mark),
            "run": self.dir.name,
            "args": self.arguments,
            "versions": package_versions(),
            "machine": self.machine,
            "code": self.code,
            "model": model,
            "resume": resume,
        }
        path = checkpoint_path(self.dir, mark)
        try:
            data = checkpoint_bytes(payload)
        except CheckpointError as e:
            raise CheckpointError(f"{path}: {e}") from None
        write_atomic(path, data)
        mean = np.mean(self.recent_returns) if self.recent_returns else float("nan")
        print(f"global_step={global_step} mark={mark} mean_return(last 20)={mean:.1f}", flush=True)


def quiet_event_writer_thread(hook_args) -> None:
    """threading.excepthook: TensorBoard's writer thread re-raises its error (a full disk) in the
    training thread at the next write, which reports it in one line; its own traceback would be a
    second report, interleaved with the first."""
    if type(hook_args.thread).__name__ == "_AsyncWriterThread" and issubclass(hook_args.exc_type, OSError):
        return
    threading.__excepthook__(hook_args)


def train_in_process(script, args) -> Path:
    """Prepares the run directory of `args` and trains it in this process with `script`, a training
    script's module, as its `main` does but raising instead of exiting; returns the run directory."""
    run = Run.prepare(args, script.ACTION_SPACE, Path(script.__file__))
    try:
        if not run.finished:
            script.train(run.args, run)
    finally:
        run.close()
    return run.dir


# gymnasium's vector envs, through whose step and reset a sub-env's (the task's) exception reaches training
VECTOR_ENV_FILES = ("sync_vector_env.py", "async_vector_env.py")


def task_failure(error: BaseException) -> str | None:
    """`the task raised X: its message, in its step()` where `error` came out of a sub-env's step or reset through
    gymnasium's vector env (the task's own code, or a wrapper on it), as the sweep says of its episodes; None for
    any other error (the training script's own, whose traceback is the report)."""
    calls = [f.name for f in traceback.extract_tb(error.__traceback__) if Path(f.filename).name in VECTOR_ENV_FILES]
    if not any(call in ("step", "reset") for call in calls):
        return None
    message = f"{type(error).__name__}: {str(error).splitlines()[0]}" if str(error) else type(error).__name__
    return f"the task raised {message}, in its {next(c for c in calls if c in ('step', 'reset'))}()"


def launch_from_command_line(args_class, description: str, kind: str, script: str, train) -> None:
    """A training script's `main`: its `Args` parsed by tyro from the command line (CleanRL's flags typed from
    habit answered first: arguments.answer_cleanrl_habits), then `launch`."""
    import tyro

    args = tyro.cli(args_class, description=description, args=answer_cleanrl_habits(sys.argv[1:]))
    launch(args, kind, script, train)


def launch(args, kind: str, script: str, train) -> None:
    """A training script's `main` after parsing: checks every argument before the disk is touched,
    prepares the run directory, and calls `train(args, run)`. Every failure is one line on stderr:
    files.exit_status's rule: exit 2 for bad arguments or a run directory that must not be used or
    cannot be written, 130 for Ctrl-C, 1 for a full disk (also when the run starts), a non-finite run, a
    task that raises in its step or reset (task_failure) or a path that disagrees with the definition (PathError;
    the earlier checkpoints kept, and named)."""
    make_env = getattr(sys.modules.get(train.__module__), "make_env", None)  # the script's: its task as it trains
    error, status = argument_error(args, kind, make_env=make_env), 2
    run = None
    if error is None:
        try:
            run = Run.prepare(args, kind, Path(script))
        except RunDirError as e:
            error = str(e)
        except OSError as e:  # write_atomic's name the file; a full disk is exit 1, a folder we may not write 2
            written = e.strerror and e.strerror.startswith("cannot write")
            error = (
                e.strerror
                if written
                else f"cannot write the run directory under {args.output_dir!r}: {e.strerror or e}"
            )
            status = exit_status(e)
    if error is not None:
        print(f"error: {error}", file=sys.stderr)
        sys.exit(status)
    for note in run.notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"run directory: {run.dir}")
    if run.finished:
        run.close()
        print(f"{run.dir} holds a finished run ({latest_checkpoint(run.dir).name}); nothing to train")
        return
    try:
        ctrl_c_handled()
        train(run.args, run)
    except (KeyboardInterrupt, OSError, NonFiniteError, CheckpointError, PathError) as e:
        latest = latest_checkpoint(run.dir)
        if isinstance(e, KeyboardInterrupt):
            kept = (
                f"checkpoints up to {latest.name} are kept: continue with --resume"
                if latest
                else "no checkpoint yet: start it again with --resume"
            )
            print(f"interrupted; {run.dir}: {kept}", file=sys.stderr)
            sys.exit(130)
        message = str(e)
        if isinstance(e, PathError):  # the checkpoints written before it passed the same check
            message += f"; checkpoints up to {latest.name} are kept" if latest else "; no checkpoint was written"
        if isinstance(e, OSError):  # write_atomic's name the file; TensorBoard's name nothing: its newest events file
            written = e.strerror and e.strerror.startswith("cannot write")
            events = sorted(run.dir.glob("events.out.tfevents.*"), key=lambda path: path.stat().st_mtime)
            message = e.strerror if written else f"cannot write {events[-1] if events else run.dir}: {e.strerror or e}"
            message += f"; checkpoints up to {latest.name} are kept" if latest else ""
        print(f"error: {message}", file=sys.stderr)
        sys.exit(1)
    except Exception as e:
        if (failed := task_failure(e)) is None:
            raise  # the script's own fault: its traceback is the report
        latest = latest_checkpoint(run.dir)
        kept = f"checkpoints up to {latest.name} are kept: fix the task and continue with --resume" if latest else (
            "no checkpoint was written: fix the task and start it again")  # fmt: skip
        print(f"error: {failed} while {run.dir} trained; {kept}", file=sys.stderr)
        sys.exit(1)
    finally:
        run.close()
