"""The checkpoint format, once for training, the sweep and every reader: file names and step marks,
finding a run's checkpoints, reading and writing them pickle-free, and what a checkpoint records of
the machine and stack that wrote it. Nothing here imports a training script."""

import importlib.metadata
import io
import math
import os
import pickle
import platform
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from pgg_utils.files import InputError, files_under, write_atomic

# 2 added what resuming needs ("resume") and the package versions; format 1 still loads for evaluation.
CHECKPOINT_FORMAT_VERSION = 2
READABLE_FORMAT_VERSIONS = (1, 2)
CHECKPOINT_GLOB = "step_*.pt"
CHECKPOINT_NAME = re.compile(r"step_(\d+)\.pt")


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
        matches = [path] if path.is_file() else files_under(path, f"checkpoints/{CHECKPOINT_GLOB}")
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


def latest_checkpoint(run_dir: Path) -> Path | None:
    found = checkpoints_of(run_dir)
    return found[-1] if found else None


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
