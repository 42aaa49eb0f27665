"""Run management for the training scripts, once: the argument check, the run directory and its lock,
the overwrite and resume rules, the checkpoint format, RNG and env-state capture, and `launch`, a
script's `main` after parsing."""

import hashlib
import importlib.metadata
import importlib.util
import io
import json
import math
import os
import pickle
import platform
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import warnings
from collections import deque
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from pgg_utils import scripts
from pgg_utils.arguments import ARGUMENT_RULES, RUN_ONLY_ARGS, run_name_error, training_arguments
from pgg_utils.files import InputError, LockedError, exit_status, lock_directory, write_atomic
from pgg_utils.guidance import schedule_error
from pgg_utils.identity import run_name
from pgg_utils.progress import Progress
from pgg_utils.startup import ctrl_c_handled

# 2 added what resuming needs ("resume") and the package versions; format 1 still loads for evaluation.
CHECKPOINT_FORMAT_VERSION = 2
READABLE_FORMAT_VERSIONS = (1, 2)
CHECKPOINT_GLOB = "step_*.pt"
CHECKPOINT_NAME = re.compile(r"step_(\d+)\.pt")
# What else the training scripts write into a run directory: TensorBoard's events, and RecordVideo's
# videos under videos/ (a resumed run's in videos/from_step_<step>/).
EVENTS_GLOB = "events.out.tfevents.*"
VIDEO_GLOBS = ("rl-video-episode-*.mp4", "from_step_*/rl-video-episode-*.mp4")


def argument_error(args, kind: str) -> str | None:
    """A one-line description of what is wrong with a training script's `args` (`kind`: discrete or
    continuous, the action space it trains), or None. Makes the env once; touches no file."""
    for name, (holds, requirement) in ARGUMENT_RULES.items():
        if hasattr(args, name) and not holds(getattr(args, name)):
            return f"--{name.replace('_', '-')} must be {requirement}, got {getattr(args, name)!r}"
    if error := schedule_error(args) or run_name_error(args.run_name):
        return error
    if args.run_name is None and (
        error := run_name_error(run_name(args), "the run name built from --env-id and --exp-name")
    ):
        return f"{error}: choose another --exp-name, or pass --run-name"
    batch_size = args.num_envs * args.num_steps
    if args.num_minibatches <= 0 or batch_size % args.num_minibatches:
        return f"--num-minibatches must divide num_envs * num_steps = {batch_size}"
    if args.norm_adv and batch_size // args.num_minibatches < 2:
        return (f"minibatches of {batch_size // args.num_minibatches} row cannot normalise advantages (a zero std): "
                "use fewer --num-minibatches, more --num-steps, or --no-norm-adv")  # fmt: skip
    if args.checkpoint_interval < batch_size:
        return f"--checkpoint-interval must be at least one batch, num_envs * num_steps = {batch_size}"
    if args.resume and args.overwrite:
        return "--resume and --overwrite exclude each other"
    if args.compile and not any(shutil.which(cxx) for cxx in (os.environ.get("CXX", "g++"), "g++", "clang++")):
        return "--compile needs a C++ compiler (g++ or clang++ on PATH, or $CXX)"
    if args.track and importlib.util.find_spec("wandb") is None:
        return "--track needs Weights and Biases: pip install wandb"
    return env_error(args.env_id, kind, args.capture_video, getattr(args, "null_dims", None))


def env_error(env_id: str, kind: str, capture_video: bool = False, null_dims=None) -> str | None:
    """Why a training script of `kind` cannot train `env_id` here (with the null embedding on `null_dims`), or None."""
    try:
        env = gym.make(env_id, render_mode="rgb_array" if capture_video else None)
    except ImportError as e:
        if env_id == "Pusher-v4":
            return "Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7, Python <= 3.11); with a newer mujoco use Pusher-v5"
        return f"cannot make environment {env_id!r}: {e}"
    except Exception as e:  # unknown ids, missing dependencies, a bad MUJOCO_GL: whatever the env's import raises
        backend = os.environ.get("MUJOCO_GL")
        hint = (f" (MUJOCO_GL={backend}: is its library installed? osmesa needs apt-get install libosmesa6, egl "
                "libegl1)" if backend and capture_video else "")  # fmt: skip
        return f"cannot make environment {env_id!r}: {e}{hint}"
    action_space, observation_space = env.action_space, env.observation_space
    error = video_error(env) if capture_video else None
    env.close()
    wanted, other = (gym.spaces.Discrete, "continuous") if kind == "discrete" else (gym.spaces.Box, "discrete")
    if not isinstance(action_space, (gym.spaces.Discrete, gym.spaces.Box)):
        return (f"{env_id} has a {type(action_space).__name__} action space; neither script trains it "
                "(ppo_pgg_discrete.py: Discrete, ppo_pgg_continuous.py: Box)")  # fmt: skip
    if not isinstance(action_space, wanted):
        return (f"{env_id} has a {type(action_space).__name__} action space; this script needs "
                f"{wanted.__name__} (use ppo_pgg_{other}.py)")  # fmt: skip
    if kind == "discrete" and not (isinstance(observation_space, gym.spaces.Box) and len(observation_space.shape) == 1):
        return f"{env_id} has a {type(observation_space).__name__} observation space; ppo_pgg_discrete.py needs a vector (1-D Box)"
    obs_dim = gym.spaces.flatdim(observation_space)
    if obs_dim == 0:
        return f"{env_id} has an empty observation space (shape {observation_space.shape}): there is no state to condition on"
    if null_dims is not None and not all(0 <= d < obs_dim for d in null_dims):
        return f"--null-dims must be observation indices of {env_id}, 0..{obs_dim - 1}, got {list(null_dims)}"
    return error


def video_error(env: gym.Env) -> str | None:
    """Why this env cannot be recorded here (a missing package or rendering backend), or None."""
    if not os.environ.get("XDG_RUNTIME_DIR"):  # SDL (pygame's renderer) complains of it at every init
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="xdg_runtime_")
    try:
        import moviepy  # noqa: F401  (gymnasium's RecordVideo writes with it)

        env.reset(seed=0)
        with warnings.catch_warnings():  # a failing GL backend warns before it raises
            warnings.simplefilter("ignore")
            if env.render() is None:
                return f"{env.spec.id} renders no frames"
    except ImportError as e:
        return f"--capture-video needs the [video] extra (pip install -e '.[video]'): {e}"
    except Exception as e:  # rendering backends fail with anything from OpenGL, pygame or MuJoCo
        hint = (
            "; headless MuJoCo needs MUJOCO_GL=egl or osmesa (apt-get install libosmesa6)"
            if "mujoco" in type(env.unwrapped).__module__
            else ""
        )
        return f"--capture-video cannot render {env.spec.id} here ({type(e).__name__}: {e}){hint}"
    return None


# --- checkpoints ---------------------------------------------------------------------------------


def checkpoint_marks(total_timesteps: int, interval: int, batch_size: int) -> list[int]:
    """Nominal steps that get a checkpoint: every multiple of `interval` below the total, and the total;
    one per iteration (interval >= batch_size), so a multiple that the last iteration passes is left
    to the total's checkpoint."""
    last_iteration = -(-total_timesteps // batch_size)
    return [m for m in range(interval, total_timesteps, interval) if -(-m // batch_size) < last_iteration] + [
        total_timesteps
    ]


def checkpoint_path(run_dir: Path, mark: int) -> Path:
    return Path(run_dir) / "checkpoints" / f"step_{mark:09d}.pt"


def checkpoint_step(path: Path) -> int | None:
    """The step mark in a checkpoint's file name, `step_<digits>.pt`; None for any other name, such as
    `step_abc.pt`: not a checkpoint the training scripts wrote, which the resume and the sweep skip with
    one line (misnamed_checkpoint) and which nothing deletes."""
    match = CHECKPOINT_NAME.fullmatch(Path(path).name)
    return int(match[1]) if match else None


def misnamed_checkpoint(path: Path) -> str:
    return f"{path}: not a checkpoint's name (step_<digits>.pt); left as it is"


def checkpoints_of(run_dir: Path) -> list[Path]:
    """A run's checkpoints, in the order of their steps (misnamed ones left out: misnamed_checkpoints)."""
    found = (Path(run_dir) / "checkpoints").glob(CHECKPOINT_GLOB)
    return sorted((path for path in found if checkpoint_step(path) is not None), key=checkpoint_step)


def misnamed_checkpoints(run_dir: Path) -> list[Path]:
    return sorted(
        path for path in (Path(run_dir) / "checkpoints").glob(CHECKPOINT_GLOB) if checkpoint_step(path) is None
    )


def find_checkpoints(paths, steps=None, skipped: list[str] | None = None) -> list[Path]:
    """The checkpoint files that `paths` name or hold (run directories, agents folders, files), once each,
    at `steps` if given, sorted; InputError with one line where a path has none. A misnamed file in a
    folder is left out, with its line appended to `skipped`; a file named on its own is taken whatever its name."""
    found = {}
    for raw in paths:
        path = Path(raw)
        if not path.exists():
            raise InputError(f"no such file or directory: {raw}")
        matches = [path] if path.is_file() else sorted(path.rglob(f"checkpoints/{CHECKPOINT_GLOB}"))
        if skipped is not None:
            skipped.extend(misnamed_checkpoint(m) for m in matches if m != path and checkpoint_step(m) is None)
        matches = [m for m in matches if m == path or checkpoint_step(m) is not None]
        if not matches:
            raise InputError(f"no checkpoints (checkpoints/{CHECKPOINT_GLOB}) under {raw}")
        for match in matches:  # one entry per file, however many of the given paths reach it
            found.setdefault(match.resolve(), match)
    found = list(found.values())
    if steps is not None:
        wanted = {checkpoint_path(Path(), s).name for s in steps}
        found = [p for p in found if p.name in wanted]
        if not found:
            raise InputError(f"no checkpoint at steps {list(steps)} under {list(paths)}")
    return sorted(found)


def unused_name(path: Path) -> Path:
    """`path`, or `path.1`, `path.2`, ...: the first that does not exist."""
    candidate, n = path, 0
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}.{n}")
    return candidate


def latest_checkpoint(run_dir: Path) -> Path | None:
    found = checkpoints_of(run_dir)
    return found[-1] if found else None


def package_versions() -> dict[str, str | None]:
    """The software stack of this process (checkpoints and sweeps keep MuJoCo versions apart)."""

    def version(package: str) -> str | None:
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"python": platform.python_version(), **{p: version(p) for p in ("torch", "numpy", "gymnasium", "mujoco")}}


def machine() -> str:
    """The CPU of this process, as `AMD EPYC, family 25 model 1, AVX2, 2 CPUs`: training's bits depend on
    it (the same code and stack trained different weights on two CPUs), so a checkpoint names it."""
    fields = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or platform.machine()
    family = f", family {fields['cpu family']} model {fields['model']}" if "cpu family" in fields else ""
    return f"{name}{family}, {torch.backends.cpu.get_cpu_capability()}, {os.cpu_count()} CPUs"


def code_revision(script: Path) -> dict:
    """The training code of a run, the script and this package: the git commit of its checkout where
    there is one (and whether those files differ from it; None where git cannot tell), and always their
    sha1, and the script's own (`script_sha1`), which a sweep compares with the file that evaluates the run.
    Taken when the run starts, before a checkout can move under it."""
    files = [Path(script).resolve(), *sorted(Path(__file__).resolve().parent.glob("*.py"))]
    digest = hashlib.sha1(b"".join(f.read_bytes() for f in files)).hexdigest()
    commit = modified = None
    try:
        git = ["git", "-C", str(files[0].parent)]
        head = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        commit = head.stdout.strip() if head.returncode == 0 else None
        if commit:
            status = subprocess.run(
                [*git, "status", "--porcelain", "--", *map(str, files)], capture_output=True, text=True, timeout=10
            )
            modified = bool(status.stdout.strip()) if status.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):  # no git
        commit = None
    return {"commit": commit, "modified": modified, "sha1": digest, "files": [f.name for f in files],
            "script_sha1": scripts.file_sha1(files[0])}  # fmt: skip


def action_bounds(ckpt: dict) -> tuple:
    """(low, high) of a continuous checkpoint's task. Checkpoints saved before the bounds were recorded
    hold ClipAction's ±inf there; the environment's own are then read from the task."""
    low, high = ckpt.get("action_low", [-math.inf]), ckpt.get("action_high", [math.inf])
    if np.isfinite(low).all() and np.isfinite(high).all():
        return low, high
    env = gym.make(ckpt["env_id"])
    low, high = env.action_space.low, env.action_space.high
    env.close()
    return low, high


def require_own(ckpt: dict, kind: str, script: str | Path, source: str | Path = "checkpoint") -> None:
    """ValueError unless `ckpt` is a checkpoint of a readable format trained by `script` (a script of
    `kind` actions, discrete/continuous), or by a script of its file name: a fork's `Agent` is its own."""
    if ckpt.get("format_version") not in READABLE_FORMAT_VERSIONS or ckpt.get("action_space") != kind:
        raise ValueError(f"{source} is not a {kind} PGG checkpoint of format {READABLE_FORMAT_VERSIONS}")
    if Path(scripts.script_name(ckpt)).name != Path(script).name:
        raise ValueError(f"{source} was trained by {scripts.script_name(ckpt)}, not {Path(script).name}: load it with "
                         "its own script's load_checkpoint, or pgg_utils.scripts.load_checkpoint")  # fmt: skip


def non_finite(state: dict) -> list[str]:
    """The names of the tensors of a state dict that hold a NaN or an infinity."""
    return [
        name
        for name, value in state.items()
        if torch.is_tensor(value) and value.is_floating_point() and not torch.isfinite(value).all()
    ]


def require_finite(ckpt: dict, source: str | Path = "checkpoint") -> None:
    """ValueError unless every weight and statistic of `ckpt` is finite: a diverged run's agent acts NaN."""
    if bad := non_finite(ckpt["model"]):
        raise ValueError(f"{source} holds non-finite weights or statistics ({', '.join(bad[:3])}); not loaded")


def read_checkpoint_file(path: Path) -> dict:
    """A checkpoint dict, pickle-free (weights_only). ValueError with one line for anything unreadable."""
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # a truncated or foreign file raises anything from pickle/zip internals
        if isinstance(e, pickle.UnpicklingError) and "allowed global" in str(e):
            # torch's message advises weights_only=False: running the file's code
            raise ValueError("not a PGG checkpoint (it holds Python objects beyond tensors and plain values, "
                             "which these scripts never write and a pickle-free load refuses)") from None  # fmt: skip
        first_line = str(e).splitlines()[0] if str(e) else ""
        raise ValueError(f"unreadable checkpoint ({type(e).__name__}: {first_line})") from None
    if not isinstance(ckpt, dict) or "model" not in ckpt:
        raise ValueError("not a PGG checkpoint")
    return ckpt


def checkpoint_bytes(payload: dict) -> bytes:
    """The file a checkpoint is saved as, proven readable: it loads back with weights_only=True, or
    CheckpointError says what in it cannot (so a run fails at its first checkpoint, not at resume)."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    data = buffer.getvalue()
    try:
        torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as e:
        raise CheckpointError(
            f"the checkpoint would not load back ({str(e).splitlines()[0] if str(e) else type(e).__name__})"
        ) from None
    return data


def export_agent(checkpoint: Path, destination: Path) -> None:
    """Writes a checkpoint as a shipped agent: everything the sweep, `--video` and `load_checkpoint`
    read (weights with the observation statistics, arguments, versions, code revision), without the
    optimizer and resume state; pickle-free (proven by loading it back) and atomic."""
    agent = {key: value for key, value in read_checkpoint_file(checkpoint).items() if key != "resume"}
    write_atomic(destination, checkpoint_bytes(agent))


class CheckpointError(Exception):
    """A checkpoint that must not be written; the message is one line."""


# --- RNG and environment state -------------------------------------------------------------------


def seed_everything(args) -> None:
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.use_deterministic_algorithms(args.torch_deterministic)
    torch.set_num_threads(args.torch_threads)


def rng_state() -> dict:
    """torch's, numpy's and Python's global generators, pickle-free."""
    numpy_state = np.random.get_state(legacy=False)
    numpy_state["state"]["key"] = torch.from_numpy(numpy_state["state"]["key"].astype(np.int64))
    return {"torch": torch.get_rng_state(), "numpy": numpy_state, "python": random.getstate()}


def set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    numpy_state = state["numpy"]
    numpy_state["state"]["key"] = numpy_state["state"]["key"].numpy().astype(np.uint32)
    np.random.set_state(numpy_state)
    random.setstate(state["python"])


# What a sub-env carries from one step to the next, besides its RNG and a MuJoCo task's simulation
# state: wrapper counters (time limit, episode statistics, reward scaling) and a classic-control task's
# physical state. Saved with a checkpoint so that a resumed run continues the very episodes it was in.
ENV_STATE_ATTRIBUTES = (
    "_elapsed_steps", "_has_reset", "episode_returns", "episode_lengths", "state", "steps_beyond_terminated",
    "discounted_return", "return_mean", "return_var", "return_count",
)  # fmt: skip


def wrapper_chain(env: gym.Env):
    while True:
        yield env
        if not isinstance(env, gym.Wrapper):
            return
        env = env.env


def pickle_free(value):
    """`value` as a weights-only checkpoint holds it: arrays as tensors, numpy scalars as Python
    numbers, inside tuples and lists too (MountainCar's state is a tuple of np.float64)."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value.copy())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, list)):
        return type(value)(pickle_free(v) for v in value)
    return value


def from_checkpoint(value):
    """The inverse of pickle_free: tensors back to (writable) numpy arrays."""
    if isinstance(value, torch.Tensor):
        return value.numpy().copy()
    if isinstance(value, (tuple, list)):
        return type(value)(from_checkpoint(v) for v in value)
    return value


def env_state(envs) -> list[dict]:
    """The state of every sub-env as plain values and tensors (pickle-free): its wrappers' counters and
    statistics, its RNG and, where it is a classic-control or MuJoCo task, the task's own state
    ("complete"; for other tasks a resumed run starts fresh episodes)."""
    states = []
    for env in envs.envs:
        task = env.unwrapped
        layers = [
            {name: pickle_free(value) for name, value in vars(layer).items() if name in ENV_STATE_ATTRIBUTES}
            for layer in wrapper_chain(env)
        ]
        kinds = [type(layer).__name__ for layer in wrapper_chain(env)]
        complete = type(task).__module__.startswith(("gymnasium.envs.classic_control", "gymnasium.envs.mujoco"))
        states.append(
            {"layers": layers, "layer_kinds": kinds, "rng": task.np_random.bit_generator.state, "complete": complete}
        )
        if hasattr(task, "data"):
            # MuJoCo: every array of mjData, not only the integration state. Quantities derived from
            # the state (body positions, contact forces) lag it by one step after mj_step, and some
            # tasks read them (Humanoid's reward and observation): mj_forward would not restore them.
            data = task.data
            arrays = {name: getattr(data, name) for name in dir(data) if not name.startswith("_")}
            states[-1]["mujoco"] = {
                name: torch.from_numpy(a.copy()) for name, a in arrays.items() if isinstance(a, np.ndarray)
            }
            states[-1]["mujoco_time"] = float(data.time)
    return states


def matched_layers(chain: list, state: dict) -> list[tuple]:
    """(wrapper, its saved attributes) by the wrappers' kinds, in order: a run resumed with another
    --capture-video has a RecordVideo more or less in its chain. Checkpoints without the kinds match by
    position."""
    if "layer_kinds" not in state:
        return list(zip(chain, state["layers"]))
    saved = list(zip(state["layer_kinds"], state["layers"]))
    matched = []
    for layer in chain:
        position = next((i for i, (kind, _) in enumerate(saved) if kind == type(layer).__name__), None)
        if position is not None:
            matched.append((layer, saved[position][1]))
            saved = saved[position + 1 :]
    return matched


def restore_env_state(envs, states: list[dict]) -> None:
    for env, state in zip(envs.envs, states):
        for layer, saved in matched_layers(list(wrapper_chain(env)), state):
            for name, value in saved.items():
                setattr(layer, name, from_checkpoint(value))
        env.unwrapped.np_random.bit_generator.state = state["rng"]
        if "mujoco" in state:
            data = env.unwrapped.data
            for name, saved in state["mujoco"].items():
                target = getattr(data, name)
                # Arrays sized by the contacts of the moment may differ in shape; the next step recomputes them.
                if target.flags.writeable and target.shape == tuple(saved.shape):
                    target[...] = saved.numpy()
            data.time = state["mujoco_time"]


# --- the run directory ---------------------------------------------------------------------------


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


def last_readable(run_dir: Path) -> tuple[Path | None, dict | None, list[tuple[Path, str]]]:
    """(the run's last checkpoint that loads, its dict, [(each later one that does not, why)]). Reads, renames
    nothing: the one walk back from the newest checkpoint that resume, the records' check and the curves share."""
    unreadable = []
    for path in reversed(checkpoints_of(run_dir)):
        try:
            return path, read_checkpoint_file(path), unreadable
        except ValueError as e:
            unreadable.append((path, str(e)))
    return None, None, unreadable


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


def differing_arguments(recorded: dict, wanted: dict, defaults: dict) -> list[str]:
    """`name recorded -> wanted` for each training argument in which a run's checkpoint differs from the
    arguments it is asked to continue with: the runs a training script refuses to continue."""
    recorded, wanted = training_arguments(recorded, defaults), training_arguments(wanted, defaults)
    return [f"{name} {recorded[name]!r} -> {wanted[name]!r}" for name in wanted if recorded[name] != wanted[name]]


class Run:
    """One training run's directory, locked while this process trains there, and its checkpoints.

    `Run.prepare` applies the rules: a directory that holds checkpoints is only continued (--resume,
    same training arguments, from its last readable checkpoint) or replaced (--overwrite), and every
    check runs before anything is deleted. A finished run is left as it is."""

    def __init__(self, args, kind: str, script: Path):
        self.args, self.kind, self.script = args, kind, Path(script)
        self.dir = Path(args.output_dir) / (args.run_name or run_name(args))
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
        run.code, run.machine = code_revision(run.script), machine()
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
            raise RunDirError(f"{error}: restore it, or pass --overwrite to start over")
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
        write_atomic(self.dir / "args.json", json.dumps(asdict(args), indent=2))

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
        if differing := differing_arguments(recorded, as_json(asdict(self.args)), as_json(self.defaults())):
            raise RunDirError(f"{self.dir} holds {what} of a run with other arguments ({', '.join(differing)}): "
                              "choose another --run-name, or pass --overwrite to replace them")  # fmt: skip

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
        differing = differing_arguments(ckpt.get("args", {}), asdict(args), self.defaults())
        if differing:
            raise RunDirError(
                f"{self.dir} holds a run with other arguments ({', '.join(differing)}): "
                "choose another --run-name, or pass --overwrite to replace it"
            )
        if not args.resume:
            finished = checkpoint_path(self.dir, args.total_timesteps).exists()
            state = "a finished run" if finished else f"an unfinished run (last checkpoint {latest.name})"
            how = "" if finished else "pass --resume to continue it, or "
            raise RunDirError(f"{self.dir} holds {state}: {how}pass --overwrite to train it again from scratch")
        if "resume" not in ckpt:
            raise RunDirError(f"{latest} predates resumable checkpoints: pass --overwrite to start over")

    def defaults(self) -> dict:
        return asdict(type(self.args)())

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
        restore_env_state(envs, state["envs"])
        next_obs = next_done = None
        if all(sub_env["complete"] for sub_env in state["envs"]):
            next_obs, next_done = state["next_obs"].numpy().copy(), state["next_done"].numpy().copy()
        set_rng_state(state["rng"])
        return state["iteration"] + 1, resumed["global_step"], next_obs, next_done

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
        atomic. `shapes`: the script's own fields (its action space and sizes)."""
        payload = {
            "format_version": CHECKPOINT_FORMAT_VERSION,
            "script": self.script.stem,
            "script_path": scripts.recorded_path(self.script),
            "action_space": self.kind,
            "env_id": self.args.env_id,
            **shapes,
            "global_step": int(global_step),
            "step_mark": int(mark),
            "args": asdict(self.args),
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


def resume_state(iteration: int, optimizer, envs, next_obs: np.ndarray, next_done: np.ndarray, schedule) -> dict:
    """What continuing a run needs besides the model: the optimizer, the sub-envs mid-episode, the
    next observation, every RNG state and, for an adaptive γ_train, the schedule's state."""
    guidance = {"guidance": schedule.state_dict()} if schedule.kind == "adaptive" else {}
    return {
        **guidance,
        "iteration": iteration,
        "optimizer": optimizer.state_dict(),
        "envs": env_state(envs),
        "next_obs": torch.from_numpy(next_obs.copy()),
        "next_done": torch.from_numpy(next_done.copy()),
        "rng": rng_state(),
    }


def train_in_process(script, args) -> Path:
    """Prepares the run directory of `args` and trains it in this process with `script`, a training
    script's module, as its `main` does but raising instead of exiting; returns the run directory."""
    run = Run.prepare(args, script.ACTION_SPACE, Path(script.__file__))
    try:
        if not run.finished:
            script.train(args, run)
    finally:
        run.close()
    return run.dir


def launch(args, kind: str, script: str, train) -> None:
    """A training script's `main` after parsing: checks every argument before the disk is touched,
    prepares the run directory, and calls `train(args, run)`. Every failure is one line on stderr:
    files.exit_status's rule: exit 2 for bad arguments or a run directory that must not be used or
    cannot be written, 130 for Ctrl-C, 1 for a full disk (also when the run starts) or a non-finite run
    (its earlier checkpoints kept)."""
    error, status = argument_error(args, kind), 2
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
        train(args, run)
    except (KeyboardInterrupt, OSError, NonFiniteError, CheckpointError) as e:
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
        if isinstance(e, OSError):  # write_atomic's name the file; TensorBoard's name nothing: its newest events file
            written = e.strerror and e.strerror.startswith("cannot write")
            events = sorted(run.dir.glob("events.out.tfevents.*"), key=lambda path: path.stat().st_mtime)
            message = e.strerror if written else f"cannot write {events[-1] if events else run.dir}: {e.strerror or e}"
            message += f"; checkpoints up to {latest.name} are kept" if latest else ""
        print(f"error: {message}", file=sys.stderr)
        sys.exit(1)
    finally:
        run.close()
