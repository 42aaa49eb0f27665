"""A run directory's records and the files the training scripts write there: which of them a fresh
start may replace, args.json, and the rule that it agrees with the checkpoints."""

import json
import re
from pathlib import Path

from pgg_utils.arguments import RUN_ONLY_ARGS
from pgg_utils.checkpoints import checkpoint_step, last_readable

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
