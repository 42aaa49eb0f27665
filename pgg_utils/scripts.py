"""Which training script a checkpoint names, found and imported, so that a checkpoint is evaluated by
the code that trained it, as CleanRL's evaluation takes `Agent` from the file that trained it.

A checkpoint records its script (`script_path`): its file name for a script at the top of the
repository (the two originals, or a fork copied beside them), its absolute path for a script elsewhere.
A checkpoint is data: its script is looked up only among the repository's top-level files and the files
the user names (`--script`), never at a path the checkpoint alone supplies. Checkpoints from before `script_path` name the script's stem
(`script`), always one of the repository's."""

import functools
import hashlib
import importlib.util
import inspect
import subprocess
import sys
from pathlib import Path

# The folder that holds the training scripts beside this package: the checkout, or site-packages.
REPOSITORY = Path(__file__).resolve().parent.parent
# The repository's own training scripts, by the action space they train.
ORIGINALS = {"discrete": "ppo_pgg_discrete", "continuous": "ppo_pgg_continuous"}


class ScriptError(ValueError):
    """A checkpoint whose script cannot be found, imported or trusted; the message is one line."""


def recorded_path(script: Path) -> str:
    """What a checkpoint records of the script that trains it: its file name where it lies at the top of the
    repository (beside the two originals), else its absolute path."""
    script = Path(script).resolve()
    return script.name if script.parent == REPOSITORY else str(script)


def script_name(ckpt: dict) -> str:
    """The name of a checkpoint's script in its configuration: the recorded path (`ppo_pgg_relu.py`,
    `/home/me/ppo_relu.py`), or the original's file name for checkpoints that record only a stem."""
    if ckpt.get("script_path"):
        return ckpt["script_path"]
    stem = ckpt.get("script") or ORIGINALS.get(ckpt.get("action_space"), "")
    return f"{stem}.py"


def original(kind: str):
    """The module of the repository's own training script for `kind` (discrete/continuous) actions."""
    return load_module(REPOSITORY / f"{ORIGINALS[kind]}.py")


def file_sha1(path: Path) -> str:
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


def given_script_error(paths) -> str | None:
    """What is wrong with a path given as --script, in one line, or None: it must be an existing Python
    file (a training script), not a folder, a missing file or another kind of file."""
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            return (
                f"--script {raw} is a folder: pass the training script file itself (--script {path / 'ppo_pgg_x.py'})"
            )
        if not path.exists():
            return f"--script {raw}: no such file"
        if path.suffix != ".py":
            return f"--script {raw} is not a Python file (.py): pass the training script that trained the checkpoints"
    return None


def locate(ckpt: dict, given: tuple[Path, ...] = ()) -> Path:
    """The file that evaluates `ckpt`: a file of `given` (--script) with the file name of its script,
    else the repository's top-level file of its recorded name. Nothing else: a name with a folder in it
    (`../x.py`, `runs/x.py`) is never looked up, so a checkpoint alone can point at no other file.
    ScriptError (one line) where no file is found."""
    name = script_name(ckpt)
    for path in given:
        if Path(path).name == Path(name).name:
            return Path(path).resolve()
    if Path(name).name != name or not name.endswith(".py"):
        which = name if Path(name).is_absolute() else "PATH"
        raise ScriptError(f"it was trained by {name}, not a script at the top of the repository ({REPOSITORY}); "
                          f"scripts are looked up there and in --script: pass --script {which} to evaluate it with "
                          "that file")  # fmt: skip
    path = REPOSITORY / name
    if not path.is_file() or path.is_symlink():
        raise ScriptError(f"its training script {name} is not in the repository ({REPOSITORY}): pass --script PATH "
                          "to evaluate it with a copy of it")  # fmt: skip
    return path


@functools.cache
def load_module(path: Path):
    """The module of a training script file, imported once per process. The repository's scripts are
    their importable modules (`import ppo_pgg_continuous` is the same object); any other file gets a
    name of its own, so that two scripts of one file name never replace each other."""
    path = Path(path).resolve()
    imported = sys.modules.get(path.stem)  # an original the caller imported already (`import ppo_pgg_continuous`)
    if imported is not None and Path(getattr(imported, "__file__", "")).resolve() == path:
        return imported
    name = f"pgg_script_{hashlib.sha1(str(path).encode()).hexdigest()[:12]}_{path.stem}"
    try:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # dataclasses resolve their fields' module through sys.modules
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as e:  # a script's import raises whatever its code raises
        sys.modules.pop(name, None)
        raise ScriptError(
            f"cannot import {path} ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})"
        ) from None
    return module


def training_module(ckpt: dict, given: tuple[Path, ...] = ()):
    """(module, file) of the script that evaluates `ckpt` (locate), checked to be a training script of
    the checkpoint's action space. ScriptError with one line otherwise."""
    path = locate(ckpt, given)
    module = load_module(path)
    missing = [
        name for name in ("Args", "ACTION_SPACE", "agent_from_checkpoint", "make_env") if not hasattr(module, name)
    ]
    if missing:
        raise ScriptError(f"{path} is not a training script of this project (it lacks {', '.join(missing)})")
    if module.ACTION_SPACE != ckpt.get("action_space"):
        raise ScriptError(f"{path} trains {module.ACTION_SPACE} actions; the checkpoint is {ckpt.get('action_space')}")
    return module, path


def load_agent(ckpt: dict, source, given: tuple[Path, ...] = ()):
    """(agent in eval mode, module, file) of a loaded checkpoint dict, by the script that evaluates it.
    ScriptError with one line where that script's `Agent` cannot load the weights."""
    module, path = training_module(ckpt, given)
    try:
        agent = module.agent_from_checkpoint(ckpt, source)
    except ValueError:  # the script's own one-line refusals (another script's checkpoint, non-finite weights)
        raise
    except Exception as e:  # load_state_dict's size mismatch (a fork whose network is another shape), or a fork's own
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ScriptError(f"{path.name}'s Agent cannot load its weights ({first})") from None
    return agent, module, path


def task_sources(env_id: str, env) -> dict[str, str]:
    """{file: sha1} of the code of a task outside gymnasium (the module of `env`'s class and, for an id
    `module:Task-v0`, the module that registers it): part of what a sweep's cell was computed with.
    gymnasium's own tasks are named by its version instead."""
    import gymnasium

    gymnasium_dir = Path(gymnasium.__file__).resolve().parent
    files = {inspect.getsourcefile(type(env.unwrapped))}
    if ":" in env_id:
        files.add(getattr(sys.modules.get(env_id.split(":")[0]), "__file__", None))
    sources = {}
    for file in filter(None, files):
        path = Path(file).resolve()
        if not path.is_relative_to(gymnasium_dir) and path.is_file():
            sources[str(path)] = file_sha1(path)
    return sources


def load_checkpoint(path, given: tuple[Path, ...] = ()):
    """(agent in eval mode, checkpoint dict) of a checkpoint file of any training script, the agent
    built by the script that trained it (locate). ValueError with one line where that cannot be done."""
    from pgg_utils.checkpoints import read_checkpoint_file  # torch: only where a checkpoint is read

    ckpt = read_checkpoint_file(path)
    return load_agent(ckpt, path, given)[0], ckpt


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
            "script_sha1": file_sha1(files[0])}  # fmt: skip


def require_own(ckpt: dict, kind: str, script: str | Path, source: str | Path = "checkpoint") -> None:
    """ValueError unless `ckpt` is a checkpoint of a readable format trained by `script` (a script of
    `kind` actions, discrete/continuous), or by a script of its file name: a fork's `Agent` is its own."""
    from pgg_utils.checkpoints import READABLE_FORMAT_VERSIONS  # torch: only where a checkpoint is read

    if ckpt.get("format_version") not in READABLE_FORMAT_VERSIONS or ckpt.get("action_space") != kind:
        raise ValueError(f"{source} is not a {kind} PGG checkpoint of format {READABLE_FORMAT_VERSIONS}")
    if Path(script_name(ckpt)).name != Path(script).name:
        raise ValueError(f"{source} was trained by {script_name(ckpt)}, not {Path(script).name}: load it with "
                         "its own script's load_checkpoint, or pgg_utils.scripts.load_checkpoint")  # fmt: skip
